"""``cartctl review FILE.rrd|RUN.csv``: a recording in the Rerun viewer with the project's layout
(``recording``), or the run metrics of CSV traces (``metrics``, ``smoothed``)."""

from __future__ import annotations

import argparse
from pathlib import Path

import cartctl.cli.commands.options as options
from cartctl.cli.commands.review.recording import VULKAN_HINT, serve_web, vulkan_available
from cartctl.errors import DataFileError, InputError

__all__ = ["add_parser", "run", "serve_web", "vulkan_available"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "review",
        help="open a recorded run in the Rerun viewer (or the metrics of a CSV trace)",
        description="Open a Rerun recording (.rrd) in the viewer with the project's layout: per "
        "motor, speed with reference and estimate above the voltage, then the loop timing. --web "
        "serves the web viewer instead, --screenshot renders the layout headless to a PNG. Given "
        "a CSV trace, print its run metrics instead (--json, --compare). Where the trace has no "
        "true speed (a real cart) or came through the serial path, the metrics on a Kalman RTS "
        "smoothed speed stand beside the encoder's (a recording's are printed before the viewer "
        "opens, its smoothed speed drawn with the speed).",
    )
    p.add_argument("recording", metavar="FILE.rrd|RUN.csv", help="a recording or a CSV trace")
    view = p.add_mutually_exclusive_group()
    view.add_argument(
        "--web",
        action="store_true",
        help="serve the web viewer and print its URL; runs until Ctrl-C",
    )
    view.add_argument(
        "--screenshot",
        metavar="FILE.png",
        help=f"render the layout headless and save a picture (needs Vulkan: {VULKAN_HINT})",
    )
    options.add_json_option(p, "CSV traces: print one JSON object instead of a table")
    p.add_argument(
        "--compare",
        metavar="OTHER.csv",
        help="CSV traces: a second run (B) beside this one (A): one table of A, B, B − A and "
        "(B − A)/|A| per metric and motor",
    )
    p.add_argument(
        "--model",
        metavar="MODEL.toml",
        help="the motor model for the smoothed speed (Kalman RTS over the trace with the recorded "
        "voltages), whose metrics stand beside the encoder's; default: the model RUN.meta.toml "
        "names (beside RUN.csv: that of the controller the run ran), else the one a run named in "
        "its recording (RUN.rrd)",
    )
    options.add_map_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    path = Path(args.recording)
    suffix = path.suffix.lower()
    if path.is_dir():
        raise InputError(
            f"{path}: is a directory; expected a Rerun recording (.rrd) or a CSV trace (.csv)"
        )
    if args.compare and suffix == ".csv":  # every file given is checked before one is read
        if Path(args.compare).suffix.lower() != ".csv":
            raise InputError(f"--compare takes a second CSV trace, got '{args.compare}'")
        options.check_input_file(args.compare, "a CSV trace", "--compare")
    if args.model:
        options.check_input_file(args.model, "a model file", "--model")
    if suffix == ".csv":
        return _review_csv(args)
    if suffix != ".rrd":
        raise InputError(
            f"review takes a Rerun recording (.rrd) or a CSV trace (.csv), got '{path}'"
        )
    if args.json or args.compare or args.map:
        raise InputError("--json, --compare and --map apply to CSV traces, not to .rrd recordings")
    options.check_outputs(args, files=("screenshot",))
    from cartctl.cli.commands.review.recording import open_in_viewer, screenshot
    from cartctl.cli.commands.review.smoothed import recording_summary

    text, extra = recording_summary(path, args.model)
    if text:
        print(text)
    if args.screenshot:
        print(f"saved {screenshot(path, Path(args.screenshot), extra=extra)}")
    elif args.web:
        serve_web(path, extra=extra)
    else:
        url = open_in_viewer(path, extra=extra)
        print(f"opened {path} in the Rerun viewer ({url})")
    return 0


def _review_csv(args: argparse.Namespace) -> int:
    if args.web or args.screenshot:
        raise InputError("--web and --screenshot apply to .rrd recordings, not to CSV traces")
    from cartctl.cli.commands.review import metrics
    from cartctl.cli.jsonout import dumps
    from cartctl.sinks.summary import format_summary

    paths = [p for p in (args.recording, args.compare) if p]
    a, *b = _summaries(paths, args)  # b: --compare's run
    if args.json:
        print(dumps(metrics.compare(a, *b) if b else a))
    else:
        print(metrics.format_compare(a, *b) if b else format_summary(a))
    return 0


def _summaries(paths: list[str], args: argparse.Namespace) -> list[dict]:
    """With --compare, --map goes to the trace(s) holding the columns it names (an own run beside a
    foreign log): one lacking them is read as it is, and refused only when neither has them."""
    from cartctl.cli.commands.review.smoothed import smooth_csv

    summaries, lacking = [], []
    for path in paths:
        try:
            summaries.append(smooth_csv(path, args.map, args.model))
        except DataFileError as err:
            if len(paths) == 1 or not err.problem.startswith("the mapping "):
                raise
            lacking.append(err)
            try:
                summaries.append(smooth_csv(path, None, args.model))
            except DataFileError:
                raise err from None
    if len(lacking) == len(paths):
        raise lacking[0]
    return summaries
