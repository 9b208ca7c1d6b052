"""The ``cartctl`` subcommands in workflow order, each with ``add_parser(subparsers)`` setting
``func`` to its ``run(args) -> int``. Their top level loads no numpy, scipy, matplotlib, Rerun or
serial stack: ``run`` does (``tests/test_startup.py``)."""

from importlib import import_module

COMMANDS = tuple(
    import_module(f"{__name__}.{name}")
    for name in [
        "excite",
        "identify",
        "inspect",
        "validate",
        "linearity",
        "design",
        "run",
        "review",
        "tune",
        "convert",
        "export",
        "virtual_cart",
        "monitor",
        "commission",
    ]
)
