"""The runtime: the per-tick controllers and estimators (pure, plain floats), and the shell that
runs them every 10 ms: clocks, the executors, real-time scheduling, the loop, and the open-loop
experiments that ``cartctl excite`` records."""
