"""Command-line options shared by several subcommands (one definition each).

This module is imported to build the parser, before any command runs: it imports no numpy, scipy
or module that does (``cartctl --help`` stays fast). The names, limits and defaults the options
show come from :mod:`cartctl.choices`, where the modules that implement them take them too.
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
from datetime import datetime
from pathlib import Path

from cartctl.choices import (
    DEFAULT_CONNECT_TIMEOUT_S,
    DEFAULT_MODEL,
    FORMS,
    MAX_DURATION_S,
    SIGNALS,
)
from cartctl.errors import InputError

__all__ = ["DEFAULT_CONNECT_TIMEOUT_S", "DEFAULT_MODEL", "FORMS", "MAX_DURATION_S", "SIGNALS"]

RERUN_MODES = ("auto", "spawn", "connect", "save", "off")
"""The choices of ``--rerun``."""


def _mapping_arg(text: str) -> dict[str, str]:
    from cartctl.data import parse_mapping

    try:
        return parse_mapping(text)
    except InputError as exc:  # argparse shows an ArgumentTypeError's own message
        raise argparse.ArgumentTypeError(str(exc)) from None


def check_duration(seconds: float, option: str = "--duration") -> float:
    """``seconds`` if it is a positive number of seconds up to :data:`MAX_DURATION_S`.

    Raises
    ------
    InputError
        Otherwise, in one line naming ``option``.
    """
    if not (math.isfinite(seconds) and 0.0 < seconds <= MAX_DURATION_S):
        raise InputError(
            f"{option} must be a positive number of seconds up to {MAX_DURATION_S:g} (24 h), "
            f"got {seconds:g}"
        )
    return seconds


def file_stem(text: str) -> str:
    """An output name that stays in its folder: no path separator, not '.' or '..', not empty."""
    if not text or text in (".", "..") or "/" in text or "\\" in text or "\0" in text:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a file name: give a name without a folder (e.g. step8) and the "
            "folder with --out"
        )
    return text


def add_name_option(p: argparse.ArgumentParser, *, default: str) -> None:
    """``--name``: the stem of the trace and recording written into ``--out``."""
    p.add_argument("--name", type=file_stem, metavar="NAME",
                   help=f"file name stem, without a folder (default {default})")  # fmt: skip


def add_output_options(p: argparse.ArgumentParser, *, name_default: str) -> None:
    """``--out DIR`` and ``--name``: where the trace and the recording go, under which name."""
    p.add_argument("--out", default="logs", metavar="DIR", help="where the trace and recording go")
    add_name_option(p, default=name_default)


def add_rerun_options(p: argparse.ArgumentParser) -> None:
    """``--rerun MODE`` and ``--connect-url``: the Rerun recording, and the viewer it goes to."""
    p.add_argument("--rerun", choices=RERUN_MODES, default="auto",
                   help="auto: record to --out and open the viewer where a display exists; spawn: "
                        "record and open the viewer; connect: record and stream to a running viewer; "
                        "save: record only; off: no recording")  # fmt: skip
    p.add_argument("--connect-url", metavar="URL", help="viewer address for --rerun connect")


def output_paths(args: argparse.Namespace, prefix: str) -> tuple[Path, Path]:
    """The trace (``.csv``) and recording (``.rrd``) paths that ``--out`` and ``--name`` ask for.

    Parameters
    ----------
    args : argparse.Namespace
        With ``out`` and ``name`` (:func:`add_output_options`).
    prefix : str
        Without ``--name`` the files are named ``PREFIX-YYYYmmdd-HHMMSS``, with ``-2``, ``-3`` …
        added when a trace or recording of that name is already in ``--out``.

    Returns
    -------
    tuple of Path
        The trace and the recording.
    """
    out = Path(args.out)
    stem = args.name or _free_stem(out, datetime.now().strftime(f"{prefix}-%Y%m%d-%H%M%S"))
    return out / f"{stem}.csv", out / f"{stem}.rrd"


def _free_stem(out: Path, stem: str) -> str:
    """``stem``, or ``stem-2``, ``stem-3`` … when a run of that name is already in ``out``."""
    candidate, n = stem, 1
    while (out / f"{candidate}.csv").exists() or (out / f"{candidate}.rrd").exists():
        n += 1
        candidate = f"{stem}-{n}"
    return candidate


def command_line(command: str) -> str:
    """The command line being run, as the files it writes record it (their provenance).

    ``cartctl`` and the process's arguments, quoted for a shell; ``cartctl COMMAND`` when the
    process has no arguments (a call from Python).
    """
    return "cartctl " + shlex.join(sys.argv[1:]) if sys.argv[1:] else f"cartctl {command}"


def add_map_option(p: argparse.ArgumentParser) -> None:
    """``--map``: which QRoboticsCenter channel is which trace column."""
    p.add_argument(
        "--map",
        type=_mapping_arg,
        metavar="COLUMN=LABEL,...",
        help="which log channel is which column, e.g. voltage_a=FloatIn2,speed_a=FloatIn0",
    )


def add_plant_options(p: argparse.ArgumentParser, *, what: str) -> None:
    """``--plant`` and the simulated plants' ``--model``, ``--preset``, ``--noise``, ``--seed``."""
    p.add_argument(
        "--plant",
        default="sim",
        metavar="PLANT",
        help=f"{what}: sim (the ARX models of --model, default), physics (the physical "
        "simulator), virtual (that simulator behind a pseudo-terminal, through the serial path; "
        "virtual:garbage=0.05,corrupt=0.05,stall=S,pull=S injects faults; physics:reverse_b=1 or "
        "virtual:reverse_b=1 wires motor b backwards) or serial:PORT (the "
        "cart, e.g. serial:/dev/ttyACM0)",
    )
    p.add_argument(
        "--model",
        default=str(DEFAULT_MODEL),
        metavar="MODEL.toml",
        help=f"model file of the sim plant (default {DEFAULT_MODEL})",
    )
    p.add_argument(
        "--preset",
        choices=("air", "ground"),
        default="ground",
        help="physics plant: wheels in the air or cart on the ground (default ground)",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=0.0,
        metavar="RAD_S",
        help="extra white measurement noise, standard deviation in rad/s (default 0: off)",
    )
    p.add_argument("--seed", type=int, default=None, help="seed of the measurement noise")
    p.add_argument(
        "--connect-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="serial and virtual carts: longest wait for the cart's first HEARTBEAT (default 5 s; "
        "opening the port resets the Arduino, which takes 1-2 s)",
    )
