"""The ``cartctl`` subcommands in workflow order, each with ``add_parser(subparsers)`` setting
``func`` to its ``run(args) -> int``. Their top level loads no numpy, scipy, matplotlib, Rerun or
serial stack: ``run`` does (``tests/test_startup.py``).
"""

from cartctl.cli.commands import (
    commission,
    convert,
    design,
    excite,
    export,
    identify,
    inspect,
    linearity,
    monitor,
    review,
    run,
    tune,
    validate,
    virtual_cart,
)

COMMANDS = (excite, identify, inspect, validate, linearity, design, run, review, tune, convert,
            export, virtual_cart, monitor, commission)  # fmt: skip
