"""Controller design on identified models: discrete PI, pole placement with integral action, the
Kalman velocity estimator, closed-loop analysis, the time-optimal bound, and controller files."""
