"""The ``cartctl`` subcommands, in the order of the workflow.

Each entry has ``add_parser(subparsers)``; the parser it adds sets ``func`` to a handler
``run(args) -> int``. Building the parser imports every command module, so their top level and
``add_parser`` import no numpy, scipy, filterpy, matplotlib, Rerun or serial stack (nor a cartctl
module that does): ``run`` imports those when the command starts (``tests/test_startup.py``).
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
