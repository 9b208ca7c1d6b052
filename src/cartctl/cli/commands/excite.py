"""``cartctl excite``: record an excitation experiment on a plant into a trace CSV."""

from __future__ import annotations

import argparse
import contextlib
import os
import stat
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cartctl.cli.commands.options as options
from cartctl import stopping
from cartctl.errors import InputError, OutputError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "excite",
        help="record an excitation experiment (input voltage, measured speed) to CSV",
        description="Drive the motors with an excitation signal and record the commanded voltage "
        "and the measured speed every 10 ms into a CSV trace (time_s, voltage_a, voltage_b, "
        "speed_a, speed_b). Simulated plants run as fast as possible, a serial or virtual cart at "
        "its own 10 ms tick (its loop delay is then in the data). The report's experiment is "
        "'--signal square --amplitude 10': +10 V, 0 V, −10 V for 1 s each, repeated.",
    )
    options.add_plant_options(p, what="what to excite")
    p.add_argument(
        "--signal",
        choices=options.SIGNALS,
        default="square",
        help="excitation shape (default square)",
    )
    p.add_argument(
        "--amplitude", type=float, required=True, metavar="V", help="peak voltage, at most 12 V"
    )
    p.add_argument(
        "--cycles",
        type=int,
        metavar="N",
        help="repetitions of the square cycle (default 5) or of the 2.56 s multisine period",
    )
    p.add_argument(
        "--duration", type=float, metavar="S", help="length of step, prbs, chirp, multisine (s)"
    )
    options.add_motor_option(
        p, "which motor gets the signal; the other stays at 0 V (default both)"
    )
    p.add_argument("--out", required=True, metavar="FILE.csv", help="where to write the trace")
    options.add_json_option(p, "print the result as one JSON object")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from cartctl.cart import SUPPLY_V
    from cartctl.cli.progress import ProgressBar
    from cartctl.data.outputs import remove_stale_recording
    from cartctl.data.trace import meta_path
    from cartctl.plants.factory import check_plant_name, make_plant
    from cartctl.runtime.loop import run_experiment
    from cartctl.runtime.realtime import gc_paused
    from cartctl.signals import make_signal
    from cartctl.sinks.csv_sink import CsvSink

    kind = check_plant_name(args.plant)
    serial = kind in ("virtual", "serial")
    amplitude_v = options.check_finite(args.amplitude, "--amplitude")
    if amplitude_v > SUPPLY_V:
        raise InputError(
            f"--amplitude {amplitude_v:g} V is beyond the cart's ±{SUPPLY_V:g} V supply"
        )
    if amplitude_v <= 0.0:
        raise InputError(f"--amplitude must be a positive peak voltage (V), got {amplitude_v:g}")
    options.check_plant_options(args)
    if args.duration is not None and args.signal == "square":
        raise InputError("--duration does not apply to the square signal; use --cycles (3 s each)")
    if args.duration is not None:
        options.check_duration(args.duration)
    read = (args.model,) if kind == "sim" else ()  # the sim plant's model file
    options.check_outputs(args, files=("out",), inputs=read)  # before anything is driven
    options.check_output_file(meta_path(args.out), "--out")
    options.check_own_trace(Path(args.out), "excite", "--out")  # an earlier excitation only
    volts = make_signal(args.signal, args.amplitude, cycles=args.cycles, duration_s=args.duration)
    ua, ub = (volts if args.motor in (m, "both") else np.zeros_like(volts) for m in "ab")
    plant, description = make_plant(
        args.plant,
        model_path=args.model,
        preset=args.preset,
        noise_std_rad_s=args.noise,
        seed=args.seed,
        connect_timeout_s=args.connect_timeout,
        motors="ab" if args.motor == "both" else args.motor,
    )
    opened: list[tuple[str, ...]] = []

    def on_open(columns: Sequence[str]) -> None:  # the meta file from the first row: a cut trace
        opened.append(tuple(columns))  # is identified in its loop (a cart's delay: at the end)
        _write_meta(
            args.out, description, None if serial else getattr(plant, "loop_delay_ticks", None)
        )
        remove_stale_recording(args.out)

    sink = CsvSink(args.out, flush_every=50 if serial else 1000, on_open=on_open)  # as run's
    bar = ProgressBar(volts.size, f"excite {args.signal}")
    try:
        # no collector pass at a random tick of a cart, and each tick answered at once: a late
        # answer raises the echo (a simulated plant has no deadline)
        with gc_paused(quick_gil=True) if serial else contextlib.nullcontext():
            result = run_experiment(
                plant, ua, ub, on_tick=bar.update, source=description, sink=sink
            )
    finally:
        bar.close()
    with stopping.deferred():  # the experiment is over: a stop signal waits for its files
        return _save(args, result, plant, description, opened)


def _write_meta(path: str | Path, description: str, loop_delay: int | None) -> Path:
    from cartctl.data.outputs import writing
    from cartctl.data.trace import meta_path, write_trace_meta

    with writing(meta_path(path)):  # the trace is kept; its meta file is not
        return write_trace_meta(path, plant=description, loop_delay_ticks=loop_delay,
                                command=options.command_line("excite"))  # fmt: skip


def _save(
    args: argparse.Namespace, result: Any, plant: Any, description: str, opened: list[Any]
) -> int:
    """The meta file written again (a cart's loop delay), the trace rewritten if its columns are
    not the streamed ones, what was done printed; the exit code."""
    from cartctl.cli.jsonout import dumps
    from cartctl.data.trace import write_trace
    from cartctl.sinks.summary import host_loss_text, warn_host_losses

    n = len(result.trace)
    if n == 0:
        print("cartctl excite: interrupted before the first tick; nothing written", file=sys.stderr)
        return stopping.exit_code()
    path = args.out
    if tuple(result.trace.columns()) != opened[0]:  # a true speed missing at a later tick
        _write_whole(lambda target: write_trace(result.trace, target), path)
    link_summary = getattr(plant, "link_summary", None)
    link = link_summary() if link_summary is not None else None
    loop_delay = (
        getattr(plant, "loop_delay_ticks", None) if link is None else link["loop_delay_ticks"]
    )  # the simulators know theirs; over serial, the echo's
    meta = _write_meta(path, description, loop_delay)
    interrupted = result.interrupted or stopping.received() is not None  # during it or after
    stopped = "failure" if result.failure else "interrupted" if interrupted else None
    if args.json:
        print(dumps({
            "trace": str(path), "ticks": n, "duration_s": n * plant.period_s,
            "signal": args.signal, "amplitude_v": args.amplitude, "motor": args.motor,
            "plant": description, "loop_delay_ticks": loop_delay, "meta": str(meta),
            "link": None if link is None else link["link"],
            "stopped": stopped,
            "failure": result.failure or None,
        }))  # fmt: skip
    else:
        print(
            f"wrote {path}: {n} ticks ({n * plant.period_s:.2f} s), {args.signal} "
            f"{args.amplitude:g} V on motor {args.motor}, plant {description}"
        )
        ticks = "unknown" if loop_delay is None else f"{loop_delay} tick(s)"
        print(f"wrote {meta}: loop delay {ticks} and the plant, for identify")
    if link is not None:  # loop_delay: the echo's
        stats = link["link"]
        if not args.json:
            print(
                f"  loop delay {loop_delay} ticks from the echo (the report's model structure for "
                f"this loop: nk = {None if loop_delay is None else loop_delay + 1}); "
                f"{stats['crc_errors']} CRC errors, {stats['lost_frames']} frames lost, "
                f"{stats['missed_ticks']} cart ticks missed; " + host_loss_text(stats)
            )
        warn_host_losses(stats, "excite")
    if stopped:
        why = f"error: {result.failure}" if result.failure else "interrupted"
        print(f"cartctl excite: {why}; the trace holds the ticks recorded so far", file=sys.stderr)
        return 1 if result.failure else stopping.exit_code()
    return 0


def _write_whole(write: Callable[[Path], object], path: str | Path) -> None:
    """``write`` the trace to ``path``; when that fails (a full disk), cut the file back to its last
    whole row, so no half row passes for data, and raise :class:`OutputError` with the rows kept."""
    path = Path(path)
    try:
        write(path)
    except OSError as exc:
        kept = 0  # rows after the header
        with contextlib.suppress(OSError):
            if stat.S_ISREG(os.stat(path).st_mode):  # a device (/dev/full) holds nothing
                with path.open("r+b") as file:
                    data = file.read()
                    whole = data.rfind(b"\n") + 1
                    file.truncate(whole)
                kept = max(0, data.count(b"\n", 0, whole) - 1)
        raise OutputError(path, f"{exc.strerror or exc}", rows=kept) from None
