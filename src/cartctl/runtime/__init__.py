"""The runtime: the per-tick controllers and estimators (pure, plain floats), and the shell that
runs them every 10 ms: clocks, the periodic executor, real-time scheduling, and the loop; with
:mod:`cartctl.runtime.experiment`, the open-loop experiments that ``cartctl excite`` records."""
