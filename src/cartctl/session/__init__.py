"""One run path below the command line.

:func:`~cartctl.session.prepare.prepare_run` loads the controller file, makes the plant and the
references, and applies every refusal a run has (:mod:`cartctl.session.checks`: a controller for
another tick or loop delay, an unstable model on the sim plant, a reference no motor can follow,
a voltage limit above the design's). ``cartctl run`` (real time and ``--fast``) and the Python
API's :func:`cartctl.simulate` both start there, so they refuse the same things with the same
line; what stays in the command is its own: options, output files, sinks and the executor.
"""
