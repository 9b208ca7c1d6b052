"""``cartctl identify FILE...``: fit motor models to recorded experiments (the report's ARX and beyond)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from cartctl.commands.options import add_map_option, command_line
from cartctl.errors import InputError

if TYPE_CHECKING:
    from cartctl.identification.arx import ArxFit
    from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, MotorIdentification


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify",
        help="fit ARX motor models to recorded experiments",
        description=(
            "Fit the report's ARX model ω[k] = −c ω[k−1] − d ω[k−2] + a v[k−nk] + b v[k−nk−1] to "
            "recorded experiments by least squares, with parameter standard deviations and fits "
            "(simulation and one-step prediction). Optionally: a Butterworth prefilter (the fit "
            "without it is shown beside), delay estimation, cycle averaging, and an output-error "
            "refinement (shown beside the ARX fit)."
        ),
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="experiment traces (CSV or QRC logs)")
    add_map_option(p)
    p.add_argument("--motor", choices=("a", "b", "both"), default="both", help="default both")
    p.add_argument(
        "--prefilter",
        choices=("none", "butter"),
        default="none",
        help="Butterworth low-pass on input and output before the fit (default none)",
    )
    p.add_argument("--order", type=int, default=6, metavar="N", help="prefilter order (default 6)")
    p.add_argument(
        "--cutoff-hz",
        type=float,
        default=20.0,
        metavar="F",
        help="prefilter cut-off frequency in Hz (default 20)",
    )
    p.add_argument(
        "--zero-phase",
        action="store_true",
        help="run the prefilter forward and backward (no lag) instead of causally",
    )
    p.add_argument(
        "--delay",
        default="2",
        metavar="auto|N",
        help="input delay nk in ticks, or 'auto' to estimate it over 1..6 (default 2)",
    )
    p.add_argument(
        "--na", type=int, default=2, metavar="N", help="number of output lags (default 2)"
    )
    p.add_argument(
        "--nb", type=int, default=2, metavar="N", help="number of input terms (default 2)"
    )
    p.add_argument(
        "--method",
        choices=("arx", "oe"),
        default="arx",
        help="arx: least squares; oe: refine by output error, ARX shown beside",
    )
    p.add_argument(
        "--average",
        action="store_true",
        help="average whole excitation cycles before the ARX fit (periodic input)",
    )
    p.add_argument("--out", metavar="MODEL.toml", help="write the models with their provenance")
    p.add_argument("--report", metavar="DIR", help="write PNG figures and a markdown summary")
    p.add_argument(
        "--compare",
        nargs="+",
        default=[],
        metavar="MODEL.toml",
        help="model files to draw on the report's pole-zero map too (e.g. models/air.toml)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (contract 3)")
    p.set_defaults(func=run)


def parse_delay(text: str) -> int | None:
    """'auto' → None (estimate), a whole number 0..50 → that delay."""
    if text == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        raise InputError(
            f"--delay must be 'auto' or a whole number of ticks, got '{text}'"
        ) from None
    if not 0 <= value <= 50:
        raise InputError(f"--delay must be in 0..50 ticks, got {value}")
    return value


def request_from_args(args: argparse.Namespace) -> IdentifyRequest:
    """Turn the command-line options into an :class:`IdentifyRequest`."""
    from cartctl.identification.pipeline import IdentifyRequest
    from cartctl.identification.prefilter import Prefilter

    prefilter = None
    if args.prefilter == "butter":
        prefilter = Prefilter(
            order=args.order, cutoff_hz=args.cutoff_hz, zero_phase=args.zero_phase
        )
    return IdentifyRequest(
        motors=("a", "b") if args.motor == "both" else (args.motor,),
        na=args.na,
        nb=args.nb,
        delay=parse_delay(args.delay),
        prefilter=prefilter,
        method=args.method,
        average=args.average,
    )


def _poles_hz(fit: ArxFit) -> str:
    parts = []
    for r in fit.model.poles():
        if r.kind == "delay":
            continue
        mark = "" if abs(r.value) < 1.0 else "!"
        parts.append(f"{r.freq_hz:.2f}{mark}")
    return ", ".join(parts) or "—"


def format_motor(res: MotorIdentification) -> str:
    """The human-readable block of one motor."""
    first = res.chosen
    names = first.theta_names()
    lines = [
        f"motor {res.motor}:  nk = {first.model.nk}"
        + (" (estimated)" if res.delay is not None else "")
    ]
    if res.cycles_averaged:
        lines[0] += f", {res.cycles_averaged} cycles averaged"
    head = f"    {'':<18}" + "".join(f"{n:>20}" for n in names)
    head += f"{'fit sim %':>11}{'fit pred %':>11}{'DC gain':>9}  poles (Hz)"
    lines.append(head)
    for label, fit in res.variants().items():
        cells = "".join(
            f"{v:>11.5g} ±{s:<7.2g}" for v, s in zip(fit.model.theta, fit.theta_std, strict=True)
        )
        lines.append(
            f"    {label:<18}{cells}{fit.fit_simulation_percent:>11.2f}{fit.fit_prediction_percent:>11.2f}"
            f"{fit.model.dc_gain():>9.4g}  {_poles_hz(fit)}"
        )
    if res.delay is not None:
        d = res.delay
        evidence = ", ".join(
            f"nk={nk}: {rms:.4g}" for nk, rms in zip(d.candidates, d.residual_rms, strict=True)
        )
        lines.append(f"    delay evidence (equation-error RMS, rad/s): {evidence}")
    return "\n".join(lines)


def format_result(result: IdentifyResult, files: list[str], request: IdentifyRequest) -> str:
    """The whole human-readable output."""
    what = f"{request.method.upper()}, na={request.na} nb={request.nb}"
    if request.prefilter:
        what += f", prefilter {request.prefilter.describe()}"
    lines = [f"identify {' '.join(files)}: {what}, Ts = {result.period_s * 1e3:g} ms", ""]
    lines += [format_motor(r) + "\n" for r in result.motors.values()]
    lines.append(
        "fit sim %: simulated from the input alone on the raw data; fit pred %: one-step-ahead "
        "prediction on the fitted data. ± is one standard deviation; '!' marks an unstable pole."
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from cartctl.data import read_trace
    from cartctl.identification.pipeline import identify, model_file
    from cartctl.jsonout import dumps
    from cartctl.modelfile import load_models, save_models

    request = request_from_args(args)
    compare = {path: load_models(path) for path in args.compare}  # fail early on a bad file
    traces = [read_trace(path, args.map) for path in args.files]
    result = identify(traces, request)
    for note in result.notes:
        print(f"cartctl identify: note: {note}", file=sys.stderr)
    if args.out:
        source = command_line("identify")
        save_models(model_file(result, args.files, request, source=source), args.out)
    if args.report:
        from cartctl.identification.summary import write_identify_report

        write_identify_report(args.report, result, traces, request, compare)
    if args.json:
        print(dumps(result.to_dict()))
        return 0
    print(format_result(result, args.files, request))
    if args.out:
        print(f"wrote {args.out}")
    if args.report:
        print(f"wrote the report to {args.report}/summary.md")
    return 0
