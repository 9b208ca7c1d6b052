"""Grid tuning: design one controller per setting, run each in the simulated loop, compare."""
