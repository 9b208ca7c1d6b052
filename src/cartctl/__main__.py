"""Allow ``python -m cartctl``."""

from cartctl.cli import main

raise SystemExit(main())
