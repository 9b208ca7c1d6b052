"""Allow ``python -m cartctl`` (the stop handlers first, as the console script has them)."""

from cartctl import stopping

stopping.install_at_start()

from cartctl.cli import console_main  # noqa: E402 - after the stop handlers

raise SystemExit(console_main())
