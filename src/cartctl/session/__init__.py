"""One run path below the command line: :func:`~cartctl.session.prepare.prepare_run` loads,
makes and checks what a run needs, so ``cartctl run`` (real time and ``--fast``) and
:func:`cartctl.simulate` refuse the same things with the same line."""
