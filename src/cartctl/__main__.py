"""Allow ``python -m cartctl``."""

from cartctl.cli import console_main

raise SystemExit(console_main())
