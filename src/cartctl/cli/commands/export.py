"""``cartctl export FILE.toml --arduino [--out FILE.h] | --mat FILE.mat``: a controller as C for
the cart's ``Robot::control()`` (:mod:`cartctl.export.arduino`), or a model or controller file
(told apart by their ``format`` line) as MATLAB ``.mat`` (:mod:`cartctl.export.mat`)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import cartctl.cli.commands.options as options
from cartctl.data.outputs import writing
from cartctl.data.tomlfile import CONTROLLER_FORMAT, MODEL_FORMAT, READABLE
from cartctl.errors import DataFileError, InputError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="write a controller as C for the cart's control() (--arduino), or a model or "
        "controller as MATLAB .mat (--mat)",
        description="--arduino: write a controller file as C for the course template's "
        "Robot::control() on the cart: per motor a state struct, cartctl_reset_a() and "
        "cartctl_step_a(reference, measured) returning the voltage, with the same difference "
        "equations, anti-windup and (steady-state) Kalman estimator as cartctl's loop. The header "
        "says how to call it. --mat: write a model file (per motor num, den, theta, theta_std, "
        "nk, Ts) or a controller file (per motor the controller's A, B, C, D from [reference; "
        "speed] to voltage, its feedback transfer function, gains, estimator gain, Ts, loop "
        "delay) as a MATLAB .mat file (scipy.io.savemat).",
    )
    p.add_argument(
        "file",
        metavar="MODEL_OR_CONTROLLER.toml",
        help="a controller file (--arduino, --mat), e.g. controllers/pi.toml, or a model file "
        "(--mat), e.g. models/ground.toml",
    )
    p.add_argument(
        "--arduino",
        action="store_true",
        help="C for the cart's Arduino (the course template on microOS)",
    )
    p.add_argument("--out", metavar="FILE.h", help="write the C here instead of to stdout")
    p.add_argument("--mat", metavar="FILE.mat", help="write a MATLAB .mat file")
    p.set_defaults(func=run)


def _command(args: argparse.Namespace) -> str:
    words = ["cartctl", "export", args.file, "--arduino"]
    if args.out:
        words += ["--out", args.out]
    return shlex.join(words)


def file_kind(path: str | Path) -> tuple[str, Path]:
    """('model' or 'controller', the file found) from the file's ``format`` line."""
    from cartctl.choices import find_file
    from cartctl.data.tomlfile import check_format, read_toml

    found = find_file(path)
    doc = read_toml(found, "model or controller file")
    fmt = doc.get("format")
    if fmt in READABLE[CONTROLLER_FORMAT]:
        return "controller", found
    if fmt in READABLE[MODEL_FORMAT] or (fmt is None and "motors" in doc and "method" not in doc):
        return "model", found
    for written, what in ((CONTROLLER_FORMAT, "controller file"), (MODEL_FORMAT, "model file")):
        if isinstance(fmt, str) and fmt.partition("/")[0] == written.partition("/")[0]:
            check_format(doc, found, written, what)  # another version: says which are read
    shown = "has no 'format' line" if fmt is None else f"has format {fmt!r}"
    raise DataFileError(
        found,
        f"is neither a model file nor a controller file ({shown}; they say format = "
        f"{MODEL_FORMAT!r} or {CONTROLLER_FORMAT!r})",
    )


def run(args: argparse.Namespace) -> int:
    if not args.arduino and not args.mat:
        raise InputError(
            "no target given; add --arduino (C for the cart's control()) or --mat FILE.mat (MATLAB)"
        )
    if args.out and not args.arduino:
        raise InputError("--out is where --arduino writes its C; for --mat give the file there")
    options.check_outputs(args, files=("out", "mat"), inputs=(args.file,))
    kind, found = file_kind(args.file)
    if args.arduino and kind != "controller":
        raise InputError(
            f"--arduino needs a controller file (e.g. controllers/pi.toml); {args.file} is a "
            "model file"
        )
    if args.mat:  # its note on stderr when the C goes to stdout
        _write_mat(kind, found, args, to_stderr=args.arduino and not args.out)
    if args.arduino:
        _write_arduino(args)
    return 0


def _write_mat(kind: str, found: Path, args: argparse.Namespace, *, to_stderr: bool) -> None:
    from cartctl.export.mat import controller_mat, model_mat, write_mat

    if kind == "model":
        from cartctl.data.modelfile import load_models

        variables = model_mat(load_models(found), source=str(args.file))
    else:
        from cartctl.design.controllerfile import load_controller

        variables = controller_mat(load_controller(found), source=str(args.file))
    write_mat(variables, args.mat)
    motors = [k.removeprefix("motor_") for k in variables if k.startswith("motor_")]
    print(
        f"wrote {args.mat} ({kind}, motor(s) {', '.join(motors)}, Ts = {variables['Ts']:g} s)",
        file=sys.stderr if to_stderr else sys.stdout,
    )


def _write_arduino(args: argparse.Namespace) -> None:
    from cartctl.design.controllerfile import load_controller
    from cartctl.export.arduino import arduino_source, timing_noise_note

    controller = load_controller(args.file)
    source = arduino_source(controller, command=_command(args))  # checks the file first
    note = timing_noise_note(controller)
    if note is not None:
        print(f"cartctl export: warning: {note}", file=sys.stderr)
    if args.out:
        with writing(args.out):
            Path(args.out).write_text(source, encoding="utf-8")
        print(f"wrote {args.out}")
    else:
        print(source, end="")
