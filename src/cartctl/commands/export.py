"""``cartctl export CONTROLLER.toml --arduino [--out FILE]``: a designed controller as C for the cart.

The C (see :mod:`cartctl.export.arduino`) goes into the course template's ``Robot::control()``,
where the controller runs with one tick of delay instead of a PC-side loop's several.
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from cartctl.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="write a designed controller as C for the cart's control() (--arduino)",
        description=(
            "Write a controller file as C for the course template's Robot::control() on the cart: "
            "per motor a state struct, cartctl_reset_a() and cartctl_step_a(reference, measured) "
            "returning the voltage, with the same difference equations, anti-windup and "
            "(steady-state) Kalman estimator as cartctl's loop. The header says how to call it."
        ),
    )
    p.add_argument("controller", metavar="CONTROLLER.toml", help="e.g. controllers/pi.toml")
    p.add_argument(
        "--arduino",
        action="store_true",
        help="C for the cart's Arduino (the course template on microOS); the only target for now",
    )
    p.add_argument("--out", metavar="FILE.h", help="write the C here instead of to stdout")
    p.set_defaults(func=run)


def _command(args: argparse.Namespace) -> str:
    words = ["cartctl", "export", args.controller, "--arduino"]
    if args.out:
        words += ["--out", args.out]
    return shlex.join(words)


def run(args: argparse.Namespace) -> int:
    if not args.arduino:
        raise InputError(
            "no target given; add --arduino (C for the cart's control(), the only target for now)"
        )
    from cartctl.design.controllerfile import load_controller
    from cartctl.export.arduino import arduino_source

    source = arduino_source(load_controller(args.controller), command=_command(args))
    if args.out:
        path = Path(args.out)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(source, encoding="utf-8")
        print(f"wrote {args.out}")
    else:
        print(source, end="")
    return 0
