"""Command-line options shared by several subcommands (one definition each)."""

from __future__ import annotations

import argparse
import math

from cartctl.data import parse_mapping
from cartctl.errors import InputError
from cartctl.plants.factory import DEFAULT_MODEL
from cartctl.signals import MAX_DURATION_S


def _mapping_arg(text: str) -> dict[str, str]:
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
        "virtual:garbage=0.05,corrupt=0.05,stall=S,pull=S injects faults) or serial:PORT (the "
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
