"""The runtime: the per-tick controllers and estimators (plain floats), and the shell that runs
them every 10 ms (clocks, executors, real-time scheduling, the loop, excite's experiments)."""
