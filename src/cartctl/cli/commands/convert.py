"""``cartctl convert FILE [--map ...] [--out FILE.csv]``: check and summarise a trace or a
QRoboticsCenter log, and write it as the trace CSV every other command reads."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cartctl.cli.commands.options as options

if TYPE_CHECKING:
    from cartctl.data.trace import Trace


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "convert",
        help="check a trace or QRoboticsCenter log, summarise it, and write it as a cartctl CSV",
        description="Read a trace (cartctl CSV, QRC 5 XML log, QRC 6 CSV log), check it (columns, "
        "numbers, sample spacing) and print a summary. QRC channels are mapped onto cartctl's "
        "columns with --map; with --out the result is written as a cartctl CSV.",
    )
    p.add_argument("file", metavar="FILE", help="trace or QRC log")
    options.add_map_option(p)
    p.add_argument("--out", metavar="FILE.csv", help="write the trace as a cartctl CSV")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def summary(trace: Trace) -> dict[str, Any]:
    """Ticks, duration, period and the range of every column."""
    import numpy as np

    return {
        "source": trace.source,
        "ticks": len(trace),
        "duration_s": float(trace.time_s[-1] - trace.time_s[0]) if len(trace) else 0.0,
        "period_s": trace.period_s,
        "columns": {
            name: {"min": float(np.min(v)), "max": float(np.max(v)), "mean": float(np.mean(v))}
            for name, v in trace.columns().items()
        },
    }


def run(args: argparse.Namespace) -> int:
    from cartctl.cli.jsonout import dumps
    from cartctl.data.outputs import remove_stale_recording, writing
    from cartctl.data.read import read_trace
    from cartctl.data.trace import meta_path, write_trace

    options.check_outputs(args, files=("out",))
    trace = read_trace(args.file, args.map)
    info = summary(trace)
    if args.out:
        write_trace(trace, args.out)  # integer channels as integers
        info["written"] = args.out
        own, beside = meta_path(args.file), meta_path(args.out)  # the loop it was recorded in
        if beside.resolve() != own.resolve():  # converted onto itself: its own is kept
            if own.is_file():  # carried over, replacing an earlier trace's of that name
                with writing(beside):
                    shutil.copyfile(own, beside)
            else:
                beside.unlink(missing_ok=True)  # an earlier trace's of that name
        remove_stale_recording(args.out, keep=Path(args.file).with_suffix(".rrd"))  # not its own
    if args.json:
        print(dumps(info))
        return 0
    print(
        f"{args.file}: {info['ticks']} ticks over {info['duration_s']:.3f} s "
        f"(period {info['period_s'] * 1e3:.2f} ms)"
    )
    print(f"  {'column':<16} {'min':>11} {'max':>11} {'mean':>11}")
    for name, c in info["columns"].items():
        print(f"  {name:<16} {c['min']:>11.4g} {c['max']:>11.4g} {c['mean']:>11.4g}")
    if args.out:
        print(f"wrote {args.out}")
    return 0
