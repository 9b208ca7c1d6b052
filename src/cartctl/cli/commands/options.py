"""Options and input/output checks shared by several subcommands. Imported to build the parser:
no numpy or scipy here; names, limits and defaults come from :mod:`cartctl.choices`."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

from cartctl.choices import (
    DEFAULT_CONNECT_TIMEOUT_S,
    DEFAULT_MODEL,
    FORMS,
    MAX_DURATION_S,
    SIGNALS,
    check_duration,
    check_finite,
    find_file,
)
from cartctl.data.outputs import check_output_file, check_output_folder
from cartctl.errors import InputError

__all__ = [
    "DEFAULT_CONNECT_TIMEOUT_S",
    "DEFAULT_MODEL",
    "FORMS",
    "MAX_DURATION_S",
    "SIGNALS",
    "check_duration",
    "check_finite",
    "check_output_file",
    "check_output_folder",
]

MAX_JOBS = 64
"""The most worker processes ``--jobs`` accepts (CPU-bound work, some 100 MB per worker)."""


def _mapping_arg(text: str) -> dict[str, str]:
    from cartctl.data.trace import parse_mapping

    try:
        return parse_mapping(text)
    except InputError as exc:  # argparse shows an ArgumentTypeError's own message
        raise argparse.ArgumentTypeError(str(exc)) from None


def check_jobs(jobs: int | None, option: str = "--jobs") -> int | None:
    """``jobs`` if None (all cores) or in 1..:data:`MAX_JOBS`, else one line naming ``option``."""
    if jobs is not None and not 1 <= jobs <= MAX_JOBS:
        raise InputError(f"{option} must be a number of processes in 1..{MAX_JOBS}, got {jobs}")
    return jobs


def seed(text: str) -> int:
    """A ``--seed``: a whole number >= 0 (numpy's generators take no other)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is a whole number >= 0, got {text!r}")
    return value


def file_stem(text: str) -> str:
    """An output name that stays in its folder: no path separator, not '.' or '..', not empty."""
    if not text or text in (".", "..") or "/" in text or "\\" in text or "\0" in text:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a file name: give a name without a folder (e.g. step8) and the "
            "folder with --out"
        )
    return text


def add_output_options(p: argparse.ArgumentParser, *, name_default: str) -> None:
    """``--out DIR`` and ``--name``: where the trace and the recording go, under which name."""
    p.add_argument("--out", default="logs", metavar="DIR", help="where the trace and recording go")
    p.add_argument("--name", type=file_stem, metavar="NAME",
                   help=f"file name stem, without a folder (default {name_default})")  # fmt: skip


def add_motor_option(
    p: argparse.ArgumentParser, help: str = "default both", default: str = "both"
) -> None:
    choices = ("a", "b", "both") if default == "both" else ("a", "b")
    p.add_argument("--motor", choices=choices, default=default, help=help)


def add_json_option(
    p: argparse.ArgumentParser, help: str = "print one JSON object (keys: docs/architecture.md)"
) -> None:
    p.add_argument("--json", action="store_true", help=help)


def add_plot_option(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--plot", metavar="FILE.png", help=f"write a PNG figure: {what}")


def add_rerun_options(p: argparse.ArgumentParser) -> None:
    """``--rerun MODE`` and ``--connect-url``: the Rerun recording, and the viewer it goes to."""
    p.add_argument("--rerun", choices=("auto", "spawn", "connect", "save", "off"), default="auto",
                   help="auto: record to --out and open the viewer where a display exists; spawn: "
                        "record and open the viewer; connect: record and stream to a running viewer; "
                        "save: record only; off: no recording")  # fmt: skip
    p.add_argument("--connect-url", metavar="URL", help="viewer address for --rerun connect")


def check_run_outputs(
    args: argparse.Namespace, prefix: str, inputs: tuple[str, ...] = ()
) -> tuple[Path, Path]:
    """The trace (``.csv``) and recording (``.rrd``) paths of ``--out`` and ``--name``, checked
    (none may be one of the ``inputs``, as in :func:`check_outputs`); without ``--name``
    ``PREFIX-YYYYmmdd-HHMMSS``, with ``-2``, ``-3`` … when that run exists;
    ``--connect-url`` only with ``--rerun connect``."""
    if args.connect_url and args.rerun != "connect":
        raise InputError(f"--connect-url is for --rerun connect, not --rerun {args.rerun}")
    out = check_output_folder(args.out, "--out")
    stem = args.name or datetime.now().strftime(f"{prefix}-%Y%m%d-%H%M%S")
    candidate, n = stem, 1
    while not args.name and any((out / f"{candidate}{s}").exists() for s in (".csv", ".rrd")):
        n += 1
        candidate = f"{stem}-{n}"
    for suffix in (".csv", ".rrd", ".meta.toml"):
        path = out / f"{candidate}{suffix}"
        if any(_same(str(path), Path(read)) for read in inputs):
            raise InputError(f"--out {path} is a file this command reads; give another --name")
        check_output_file(path, "--out")
    check_own_trace(out / f"{candidate}.csv", prefix, "--name")
    return out / f"{candidate}.csv", out / f"{candidate}.rrd"


_KINDS = {
    "run": "a run's trace",
    "excite": "an excitation",
    "monitor": "a trace without a .meta.toml (a monitor's, a converted log)",
}


def check_own_trace(trace: Path, command: str, option: str) -> None:
    """Refuse to replace ``trace`` unless ``command`` recorded it (an earlier output of its own):
    its .meta.toml names a run's controller (before 9082b29: its command line), an excitation's
    none; ``monitor`` writes none. A trace without rows (a full disk as it began) holds nothing."""
    if not trace.is_file():
        return
    with trace.open("rb") as file:
        if not (file.readline() and file.readline()):  # no row: its meta file may be cut too
            return
    from cartctl.data.trace import read_trace_meta

    meta = read_trace_meta(trace)
    ran = meta is not None and (meta.controller or meta.command.split()[1:2] == ["run"])
    kind = "monitor" if meta is None else "run" if ran else "excite"
    if kind != command:
        raise InputError(
            f"{option}: {trace} holds {_KINDS[kind]}; cartctl {command} replaces "
            f"only {_KINDS[command]}: give another {option} or remove it"
        )


def check_outputs(
    args: argparse.Namespace,
    *,
    files: tuple[str, ...] = (),
    folders: tuple[str, ...] = (),
    inputs: tuple[str, ...] = (),
) -> None:
    """The output options given, named by their ``args`` attribute (``"out"`` is ``--out``),
    checked as files or folders before any work; an output file that is one of the ``inputs``
    (the files the command reads) is refused: it would be replaced by another kind of file."""
    read = [find_file(path) for path in inputs]  # as the command finds them: a shipped model
    for names, check in ((files, check_output_file), (folders, check_output_folder)):
        for name in names:
            value = getattr(args, name, None)
            option = "--" + name.replace("_", "-")
            if value and check is check_output_file and any(_same(value, p) for p in read):
                raise InputError(f"{option} {value} is a file this command reads; give another")
            if value:
                check(value, option)


def _same(out: str, read: Path) -> bool:
    """Whether the output path ``out`` is the file ``read`` (through links, or as paths)."""
    if os.path.exists(out) and os.path.exists(read):  # (False for a name too long)
        return os.path.samefile(out, read)
    return Path(out).resolve() == read.resolve()


def command_line(command: str) -> str:
    """The command line being run, as the files it writes record it (``cartctl COMMAND`` when
    called from Python without arguments)."""
    return "cartctl " + shlex.join(sys.argv[1:]) if sys.argv[1:] else f"cartctl {command}"


def add_map_option(p: argparse.ArgumentParser) -> None:
    """``--map``: which QRoboticsCenter channel is which trace column."""
    p.add_argument(
        "--map",
        type=_mapping_arg,
        metavar="COLUMN=LABEL,...",
        help="which log channel is which column, e.g. voltage_a=FloatIn2,speed_a=FloatIn0",
    )


class Given(argparse.Action):
    """Store the value and note the option in ``args.given``: an option the command does not use
    (the plant's, the design method's) is refused only when given, even at its default value."""

    def __call__(self, parser: Any, namespace: Any, values: Any, option: Any = None) -> None:
        setattr(namespace, self.dest, values)
        namespace.given = getattr(namespace, "given", frozenset()) | {self.option_strings[0]}


def add_plant_options(p: argparse.ArgumentParser, *, what: str) -> None:
    """``--plant`` and the simulated plants' ``--model``, ``--preset``, ``--noise``, ``--seed``,
    ``--connect-timeout``."""
    p.add_argument(
        "--plant",
        default="sim",
        metavar="PLANT",
        help=f"{what}: sim (the ARX models of --model, default), physics (the physical "
        "simulator), virtual (that simulator behind a pseudo-terminal, through the serial path; "
        "virtual:garbage=0.05,corrupt=0.05,stall=S,pull=S,late=0.3 injects faults; physics:reverse_b=1 or "
        "virtual:reverse_b=1 wires motor b backwards) or serial:PORT (the "
        "cart, e.g. serial:/dev/ttyACM0)",
    )
    p.add_argument(
        "--model",
        action=Given,
        default=str(DEFAULT_MODEL),
        metavar="MODEL.toml",
        help=f"model file of the sim plant (default {DEFAULT_MODEL})",
    )
    p.add_argument(
        "--preset",
        action=Given,
        choices=("air", "ground"),
        default="ground",
        help="physics plant: wheels in the air or cart on the ground (default ground)",
    )
    p.add_argument(
        "--noise",
        action=Given,
        type=float,
        default=0.0,
        metavar="RAD_S",
        help="extra white measurement noise, standard deviation in rad/s (default 0: off)",
    )
    p.add_argument(
        "--seed", type=seed, default=None, action=Given, help="seed of the measurement noise"
    )
    p.add_argument(
        "--connect-timeout",
        action=Given,
        type=float,
        default=DEFAULT_CONNECT_TIMEOUT_S,
        metavar="S",
        help="serial and virtual carts: longest wait for the cart's first HEARTBEAT (default 5 s; "
        "opening the port resets the Arduino, which takes 1-2 s)",
    )


def check_input_file(path: str | Path, what: str, option: str | None = None) -> Path:
    """The file ``path`` names (a shipped file's relative path finds the shipped one), checked
    before the work that needs it; else one line naming ``option`` (None: a positional) and
    ``path``, ``is a directory`` or ``not found``, and ``what`` it should be."""
    found = find_file(path)
    lead = f"{option} {path}" if option else str(path)
    if found.is_dir():
        raise InputError(f"{lead}: is a directory; expected {what}")
    if not found.is_file():
        raise InputError(f"{lead}: not found; expected {what}")
    return found


def check_plant_options(args: argparse.Namespace, named: str = "--plant") -> None:
    """:func:`cartctl.plants.factory.check_plant_options` on the options the command has;
    ``named``: how the plant was given (``PLANT``: a positional)."""
    from cartctl.plants.factory import check_plant_options as check

    noise, timeout = getattr(args, "noise", 0.0), getattr(args, "connect_timeout", 1.0)
    given = getattr(args, "given", ())  # (virtual-cart has no --plant, so nothing given here)
    plant = getattr(args, "plant", "")
    check(plant, noise_std_rad_s=noise, connect_timeout_s=timeout, given=given, named=named)
