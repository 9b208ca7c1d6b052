"""``cartctl identify FILE...``: fit motor models to recorded experiments (ARX and beyond)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import cartctl.cli.commands.options as options
from cartctl.errors import InputError

if TYPE_CHECKING:
    from cartctl.data.modelfile import ModelFile
    from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, MotorIdentification
    from cartctl.model import ArxModel


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "identify",
        help="fit ARX motor models to recorded experiments",
        description="Fit the report's ARX model ω[k] = −c ω[k−1] − d ω[k−2] + a v[k−nk] + b "
        "v[k−nk−1] to recorded experiments by least squares, with parameter standard deviations "
        "and fits (simulation and one-step prediction). Optionally: a Butterworth prefilter (the "
        "fit without it is shown beside), delay estimation, cycle averaging, and an output-error "
        "refinement (shown beside the ARX fit). Every chosen model gets residual tests (the "
        "one-step prediction errors' autocorrelation and cross-correlation with the input against "
        "99 % bounds) and, in the report, 1σ/2σ bands on its Bode plot from θ's covariance.",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="experiment traces (CSV or QRC logs)")
    options.add_map_option(p)
    options.add_motor_option(p)
    p.add_argument(
        "--prefilter",
        choices=("none", "butter"),
        default="none",
        help="Butterworth low-pass on input and output before the fit (default none)",
    )
    p.add_argument(
        "--order", type=int, default=6, metavar="N", help="prefilter order, 1..12 (default 6)"
    )
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
        help="input delay nk in ticks, or 'auto' to estimate one for both motors over 1..6 "
        "(default 2)",
    )
    p.add_argument(
        "--loop-delay",
        type=int,
        metavar="N",
        help="the loop delay the data was recorded in (ticks from a measurement to its voltage on "
        "the motor), written into the model for design; default: from the traces' .meta.toml "
        "files (excite and run write them), else unknown",
    )
    p.add_argument(
        "--na", type=int, default=2, metavar="N", help="number of output lags, 0..50 (default 2)"
    )
    p.add_argument(
        "--nb", type=int, default=2, metavar="N", help="number of input terms, 1..50 (default 2)"
    )
    p.add_argument(
        "--method",
        choices=("arx", "oe"),
        default="arx",
        help="arx: least squares; oe: refine by output error, ARX shown beside (na + nb up to "
        "10: its cost grows fast with the order)",
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
        help="model files to compare with (e.g. models/air.toml): their fits in the table and "
        "JSON, their Bode plots against the empirical transfer function and their poles and zeros "
        "in the report",
    )
    p.add_argument(
        "--orders",
        nargs="?",
        const="",
        default=None,
        metavar="SPEC",
        help="fit ARX for every na, nb, nk of a grid and print loss, AIC, FPE and the simulation "
        "fit (on the validation data, if any), marking the best; SPEC like na=1:3,nb=1:3,nk=1:4 (ranges inclusive, "
        "keys left out keep these defaults; each order up to 50, at most 400 combinations and "
        "a sum of (na + nb)² over them up to 40000)",
    )
    val = p.add_mutually_exclusive_group()
    val.add_argument(
        "--validate-on",
        action="append",
        default=[],
        metavar="FILE",
        help="an independent experiment to validate on: fits and residual tests are on it "
        "(repeatable)",
    )
    val.add_argument(
        "--split",
        type=float,
        metavar="F",
        help="estimate on the first fraction F of each experiment (e.g. 0.7), validate on the rest",
    )
    options.add_json_option(p)
    p.set_defaults(func=run)


def parse_delay(text: str) -> int | None:
    """'auto' → None (estimate), a whole number → that delay (its range: arx.check_orders')."""
    if text == "auto":
        return None
    try:
        return int(text)
    except ValueError:
        raise InputError(
            f"--delay must be 'auto' or a whole number of ticks, got '{text}'"
        ) from None


def request_from_args(
    args: argparse.Namespace, loop_delay_ticks: int | None = None
) -> IdentifyRequest:
    """The options as an :class:`IdentifyRequest`; ``loop_delay_ticks`` (the traces' meta files)
    when ``--loop-delay`` is not given."""
    from cartctl.identification.orders import parse_grid
    from cartctl.identification.pipeline import IdentifyRequest, Prefilter

    prefilter = None  # first: its refusal comes before those of the grid and the delay
    shape = (("--order", "order"), ("--cutoff-hz", "cutoff_hz"), ("--zero-phase", "zero_phase"))
    given = [o for o, f in shape if getattr(args, f) != getattr(Prefilter, f)]  # not the default
    if args.prefilter != "butter" and given:
        need = "needs" if len(given) == 1 else "need"
        raise InputError(f"{' and '.join(given)} {need} --prefilter butter")
    if args.prefilter == "butter":
        prefilter = Prefilter(**{field: getattr(args, field) for _, field in shape})
    return IdentifyRequest(
        orders=None if args.orders is None else parse_grid(args.orders),
        split=args.split,
        motors=("a", "b") if args.motor == "both" else (args.motor,),
        na=args.na,
        nb=args.nb,
        delay=parse_delay(args.delay),
        prefilter=prefilter,
        method=args.method,
        average=args.average,
        loop_delay_ticks=loop_delay_ticks if args.loop_delay is None else args.loop_delay,
    )


def _poles_hz(model: ArxModel) -> str:
    parts = [
        f"{r.freq_hz:.2f}{'' if abs(r.value) < 1.0 else '!'}"
        for r in model.poles()
        if r.kind != "delay"
    ]
    return ", ".join(parts) or "—"


def format_motor(res: MotorIdentification, compared: Mapping[str, ArxModel]) -> str:
    """One motor's block: the report's fit table (with the ``--compare`` models' rows), the delay
    evidence, the residual tests and the orders table."""
    from cartctl.identification.report import fit_rows
    from cartctl.measures.numfmt import render_table

    lines = [f"motor {res.motor}:  nk = {res.chosen.model.nk}"]
    lines[0] += " (estimated)" if res.delay is not None else ""
    if res.cycles_averaged:
        lines[0] += f", {res.cycles_averaged} cycles averaged"
    rows = fit_rows(res, compared)
    models = [fit.model for fit in res.variants().values()] + list(compared.values())
    for row, model in zip(rows, models, strict=True):
        row["poles (Hz)"] = _poles_hz(model)  # '!' on an unstable pole
    tail = ["fit sim (%)", "fit pred (%)", "DC gain (rad/s/V)", "poles (Hz)"]
    theta = [
        k for k in dict.fromkeys(k for r in rows for k in r) if k not in ("model", "nk", *tail)
    ]
    headers = ["nk", *sorted(theta, key=lambda k: k.endswith("(rad/s/V)")), *tail]  # outputs first
    cells = [[row["model"], *(str(row.get(h, "")) for h in headers)] for row in rows]
    lines += render_table(["", *headers], cells, indent="    ")
    lines += [f"    OE: {note}" for note in getattr(res.oe, "notes", ())]
    diag = res.diagnostics
    if res.delay is not None:
        d = res.delay
        evidence = ", ".join(
            f"nk={nk}: {rms:.3g}" for nk, rms in zip(d.candidates, d.residual_rms, strict=True)
        )
        alone = "" if d.nk_alone is None else f" (on its own: nk = {d.nk_alone})"
        lines.append(f"    delay evidence (equation-error RMS, rad/s): {evidence}{alone}")
    lines.append(f"    {diag.residuals.summary()}")
    if diag.orders is not None:
        lines.append(f"    orders (ARX; fits on the {diag.orders.fit_on} data):")
        lines.append(diag.orders.format())
    return "\n".join(lines)


def _nk_remark(result: IdentifyResult, delay: int) -> str:
    nks = sorted({r.chosen.model.nk for r in result.motors.values()})
    if nks == [delay + 1]:
        return f" (nk = {delay + 1} = loop delay + 1: the report's timing)"
    if 0 in nks:
        return " (nk = 0: design, tune and the sim plant refuse it; they need nk >= 1)"
    return f" (nk = {', '.join(map(str, nks))}; design explains how it treats that)"


def format_result(
    result: IdentifyResult,
    files: list[str],
    request: IdentifyRequest,
    compare: dict[str, ModelFile],
) -> str:
    """The whole human-readable output."""
    from cartctl.data.trace import meta_path

    what = f"{request.method.upper()}, na={request.na} nb={request.nb}"
    if request.prefilter:
        what += f", prefilter {request.prefilter.describe()}"
    lines = [f"identify {' '.join(files)}: {what}, Ts = {result.period_s * 1e3:g} ms", ""]
    for m, r in result.motors.items():
        models = {
            f"{Path(p).stem} (file)": f.motors[m] for p, f in compare.items() if m in f.motors
        }
        lines.append(format_motor(r, models) + "\n")
    if result.delay is not None:
        j = result.delay
        evidence = ", ".join(
            f"nk={c}: {e:.4g}" for c, e in zip(j.candidates, j.evidence_rad_s, strict=True)
        )
        lines.append(
            f"delay nk = {j.nk} for both motors (one loop), from the joint evidence (weighted "
            f"geometric mean of the motors' equation-error RMS, rad/s): {evidence}"
        )
    delay = result.loop_delay_ticks
    meta = any(meta_path(path).is_file() for path in files)  # a killed cart excite's has none
    why = "the .meta.toml beside the data records none" if meta else "no .meta.toml beside the data"
    lines.append(
        f"loop delay: unknown ({why}; --loop-delay N states it)"
        if delay is None
        else f"loop delay: {delay} tick(s), written into the model for design"
        + ("" if not result.motors else _nk_remark(result, delay))
    )
    lines.append("")
    on = next((r.diagnostics.fit_on for r in result.motors.values()), "estimation")
    where = (
        "fit sim and fit pred (%): on the validation data, simulated from its input and predicted "
        "one step ahead. "
        if on == "validation"
        else "fit sim (%): simulated from the input alone on the raw data; fit pred (%): "
        "one-step-ahead prediction on the fitted data. "
    )
    lines.append(
        where + "± is one standard deviation; θ's first na entries are output coefficients "
        "(–), the rest input coefficients (rad/s/V); '!' marks an unstable pole. Residual "
        f"tests on the {on} data."
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from cartctl.cli.jsonout import dumps
    from cartctl.data.modelfile import load_models, save_models
    from cartctl.data.read import read_trace
    from cartctl.data.trace import loop_delay_of
    from cartctl.identification.pipeline import identify, model_file
    from cartctl.identification.validate import PERIOD_TOLERANCE

    inputs = (*args.files, *(args.validate_on or ()), *(args.compare or ()))
    options.check_outputs(args, files=("out",), folders=("report",), inputs=inputs)
    if args.report:  # its summary, written last, as well as the folder
        options.check_output_file(Path(args.report) / "summary.md", "--report")
    recorded = loop_delay_of(args.files)  # the traces' meta files; they must agree
    if args.loop_delay is not None and recorded is not None and recorded != args.loop_delay:
        print(
            f"cartctl identify: warning: --loop-delay {args.loop_delay} overrides the loop delay "
            f"{recorded} recorded with the data",
            file=sys.stderr,
        )
    request = request_from_args(args, recorded)
    compare = {path: load_models(path) for path in args.compare}  # fail early on a bad file
    traces = [read_trace(path, args.map) for path in args.files]
    for path, models in compare.items():  # simulated on the data: the period must be theirs
        if abs(traces[0].period_s - models.period_s) > PERIOD_TOLERANCE * models.period_s:
            raise InputError(
                f"--compare {path}: the model has Ts = {models.period_s * 1e3:.4g} ms but "
                f"{traces[0].source} is sampled every {traces[0].period_s * 1e3:.4g} ms; compare "
                "models of the data's period"
            )
    validation = [read_trace(path, args.map) for path in args.validate_on]
    result = identify(traces, request, validation)
    for note in result.notes:
        print(f"cartctl identify: note: {note}", file=sys.stderr)
    if args.out:
        source = options.command_line("identify")
        save_models(model_file(result, args.files, request, source=source), args.out)
    if args.report:
        from cartctl.identification.report import write_identify_report

        write_identify_report(args.report, result, traces, request, compare)
    if args.json:
        doc = result.to_dict()
        for motor, res in result.motors.items():
            labels = {path: mf.motors[motor] for path, mf in compare.items() if motor in mf.motors}
            if labels:
                doc["motors"][motor]["compared"] = res.diagnostics.compared_fits(labels)
        print(dumps(doc))
        return 0
    print(format_result(result, args.files, request, compare))
    if args.out:
        print(f"wrote {args.out}")
    if args.report:
        print(f"wrote the report to {args.report}/summary.md")
    return 0
