"""cartctl: identify, design and run velocity control of a two-wheeled DC-motor cart.

Pipeline: ``data`` → ``identify`` → ``models/`` → ``design`` → ``controllers/`` →
``runtime`` (plant, estimator, controller, sinks) → ``logs/`` → review.
"""

__version__ = "0.1.0"

TS_S: float = 0.01
"""The cart's control period in seconds (microOS runs its control thread every 10 ms)."""
