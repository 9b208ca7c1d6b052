"""One run path below the command line: ``prepare.prepare_run``, so ``cartctl run`` and
:func:`cartctl.simulate` refuse the same things with the same line."""
