"""Per-tick objects the 10 ms loop runs: controllers and speed estimators (pure, no clock, no I/O)."""
