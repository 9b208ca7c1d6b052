"""The ``cartctl`` subcommands, in the order of the workflow.

Each entry has ``add_parser(subparsers)``; the parser it adds sets ``func`` to a handler
``run(args) -> int``.
"""

from cartctl.commands import (
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
            export, virtual_cart, monitor)  # fmt: skip
