"""``cartctl tune MODEL.toml --method pi|poles``: a grid of designs, each run in the simulated loop.

Between ``design`` and ``run``. Each grid setting (see :mod:`cartctl.design.tune` for ``--grid``)
is designed per motor by the design command's own code, then run in the loop of
``cartctl run --fast`` (ControlLoop, PeriodicExecutor, VirtualClock; a MemorySink only, no files)
and summarised by the run summary's ``trace_metrics``. The table compares the worse of motors a
and b per metric and marks the Pareto front; ``--choose N --out FILE`` writes setting N's
controller file through ``cartctl design`` itself.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import shlex
import sys
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.commands import design
from cartctl.design.tune import (
    AXES,
    TuneResult,
    design_argv,
    grid_settings,
    mark_pareto,  # fmt: skip
    parse_grid,
    sort_results,
)
from cartctl.errors import CartctlError, InputError, PlantError
from cartctl.modelfile import ModelFile, load_models
from cartctl.plants.base import Plant
from cartctl.plants.factory import make_plant
from cartctl.progress import ProgressBar
from cartctl.runtime.base import Controller
from cartctl.runtime.loop import ControlLoop, MemorySink
from cartctl.runtime.reference import FORMS, reference_signal
from cartctl.sinks.summary import trace_metrics


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune",
        help="design a grid of controllers, run each in the simulated loop, show the Pareto front",
        description=(
            "Design one controller per grid setting (pi: phase margin × crossover; poles: settling "
            "time × overshoot), run each like 'cartctl run --fast' against a simulated plant and "
            "compare overshoot, settling time, RMS error and peak voltage (the worse of motors a "
            "and b). Grid: comma-separated NAME=START:STOP:STEP (inclusive) or NAME=VALUE; pi "
            "axes phase_margin (deg, default 50:75:5), crossover_hz (Hz, 2:5:0.5); poles axes "
            "settling_time (s, 0.04:0.16:0.02), overshoot (%%, 0.5:5:1.5)."
        ),
    )
    p.add_argument("model", metavar="MODEL.toml", help="model to design on (and of the sim plant)")
    p.add_argument("--method", choices=tuple(AXES), required=True)
    p.add_argument(
        "--grid", metavar="SPEC", help="e.g. 'phase_margin=50:75:5,crossover_hz=2:5:0.5'"
    )
    p.add_argument("--plant", default="sim", choices=("sim", "physics"), help="default sim (MODEL)")
    p.add_argument("--preset", choices=("air", "ground"), default="ground", help="physics preset")
    p.add_argument("--reference", default="step:10", metavar="SPEC",
                   help=f"speed reference of both motors (default step:10): {FORMS}")  # fmt: skip
    p.add_argument(
        "--duration", type=float, default=2.0, metavar="S", help="run time (default 2 s)"
    )
    p.add_argument("--extra-delay", type=int, default=0, metavar="N",
                   help="ticks of delay the design allows for (the simulated loop has none, as in run --fast)")  # fmt: skip
    p.add_argument("--jobs", type=int, metavar="N", help="worker processes (default: all cores)")
    p.add_argument("--plot", metavar="FILE.png", help="settling time vs overshoot scatter")
    p.add_argument(
        "--choose", type=int, metavar="N", help="write setting #N's controller (with --out)"
    )
    p.add_argument("--out", metavar="CONTROLLER.toml", help="where --choose writes the controller")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


@dataclass(frozen=True)
class TuneJob:
    """A chunk of settings for one worker, with what every setting shares (picklable)."""

    model: str
    method: str
    plant: str
    preset: str
    reference: str
    duration_s: float
    extra_delay_ticks: int
    items: tuple[tuple[int, dict[str, float]], ...]


def _design_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cartctl")
    design.add_parser(parser.add_subparsers())
    return parser


def simulate(
    plant: Plant,
    controllers: Mapping[str, Controller],
    references: Mapping[str, NDArray[np.float64]],
    *,
    period_s: float,
    voltage_limit_v: float,
) -> tuple[dict[str, Any], str | None]:
    """The loop of ``cartctl run --fast``, kept in memory.

    Parameters
    ----------
    plant, controllers, references
        As for :class:`~cartctl.runtime.loop.ControlLoop`; references in rad/s, one per tick.
    period_s : float
        Tick period (s).
    voltage_limit_v : float
        Command clamp (V).

    Returns
    -------
    summary : dict
        ``trace_metrics`` of the run (as ``cartctl run --json`` without file names).
    failure : str or None
        The plant's error, if it failed.
    """
    from cartctl.runtime.clock import VirtualClock
    from cartctl.runtime.executor import PeriodicExecutor

    clock, memory = VirtualClock(), MemorySink()
    loop = ControlLoop(plant, controllers, references, [memory], now_s=clock.now_s,
                       voltage_limit_v=voltage_limit_v, period_s=period_s)  # fmt: skip
    executor = PeriodicExecutor(period_s, clock, max_ticks=len(references["a"]))
    try:
        loop.start()

        def tick(k: int) -> bool:
            return loop.tick(
                k, executor.period_error_us, executor.start_s, executor.grid_index * period_s
            )

        executor.run(tick)
    except PlantError as exc:
        loop.state.failure = str(exc)
    finally:
        loop.finish()
    return trace_metrics(memory.arrays(), period_s), loop.state.failure


def _evaluate(job: TuneJob, models: ModelFile, parser: argparse.ArgumentParser,
              index: int, settings: dict[str, float]) -> TuneResult:  # fmt: skip
    argv = design_argv(job.model, job.method, settings, job.extra_delay_ticks)
    args = parser.parse_args(["design", *argv])
    controllers: dict[str, Controller] = {}
    for m in ("a", "b"):
        try:
            controllers[m] = design._design_motor(args, models.motor(m))[0]
        except (CartctlError, np.linalg.LinAlgError) as exc:
            return TuneResult(index, settings, False, f"motor {m}: {exc}")
    plant, _ = make_plant(job.plant, model_path=job.model, preset=job.preset)
    n = max(1, round(job.duration_s / plant.period_s))
    refs = {m: reference_signal(job.reference, n, plant.period_s, m) for m in ("a", "b")}
    summary, failure = simulate(plant, controllers, refs, period_s=plant.period_s,
                                voltage_limit_v=min(12.0, args.voltage_limit))  # fmt: skip
    if failure:
        return TuneResult(index, settings, False, f"the run failed: {failure}")
    return TuneResult(index, settings, True, motors=summary["motors"])


def evaluate_chunk(job: TuneJob) -> list[TuneResult]:
    """Design and run every setting of a chunk (the worker function of the process pool)."""
    models, parser = load_models(job.model), _design_parser()
    return [_evaluate(job, models, parser, i, s) for i, s in job.items]


def _check(args: argparse.Namespace, n_settings: int) -> None:
    if not (math.isfinite(args.duration) and args.duration > 0):
        raise InputError(f"--duration must be a positive number of seconds, got {args.duration}")
    if args.extra_delay < 0:
        raise InputError(f"--extra-delay must be >= 0 ticks, got {args.extra_delay}")
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs must be a number of processes >= 1, got {args.jobs}")
    if (args.choose is None) != (args.out is None):
        raise InputError("--choose N and --out CONTROLLER.toml go together; give both or neither")
    if args.choose is not None and not 1 <= args.choose <= n_settings:
        raise InputError(f"--choose must be a setting number in 1..{n_settings}, got {args.choose}")
    models = load_models(args.model)
    plant, _ = make_plant(args.plant, model_path=args.model, preset=args.preset)
    plant.close()
    if abs(plant.period_s - models.period_s) > 1e-9:
        raise InputError(
            f"the model is for Ts = {models.period_s} s but the plant ticks at {plant.period_s} s"
        )
    reference_signal(args.reference, 1, plant.period_s)  # a bad spec fails here, once


def _run_grid(job: TuneJob, jobs: int) -> list[TuneResult]:
    items = job.items
    bar = ProgressBar(len(items), "cartctl tune")
    results: list[TuneResult] = []
    # The first setting runs here in any case: its lazy imports and first-call costs are then
    # paid once, before the workers are forked, rather than once in every worker.
    for item in items if jobs == 1 else items[:1]:
        results += evaluate_chunk(replace(job, items=(item,)))
        bar.update(len(results))
    if len(items) > 1 and jobs > 1:
        rest = items[1:]
        size = max(1, math.ceil(len(rest) / (4 * jobs)))
        chunks = [replace(job, items=rest[i : i + size]) for i in range(0, len(rest), size)]
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(chunks)))
        try:
            for future in as_completed([pool.submit(evaluate_chunk, c) for c in chunks]):
                results += future.result()
                bar.update(len(results))
        finally:
            pool.shutdown(cancel_futures=True)
    bar.close()
    return sorted(results, key=lambda r: r.index)


def _num(x: float | None, fmt: str, scale: float = 1.0) -> str:
    return "—" if x is None else format(x * scale, fmt)


def format_table(method: str, results: Sequence[TuneResult]) -> str:
    """One row per setting; ``*`` marks the Pareto front; infeasible reasons below the table."""
    axes = AXES[method]
    heads = [f"{a.name} ({a.unit})" for a in axes]
    lines = ["   #  " + "".join(f"{h:>19}" for h in heads)
             + f"{'overshoot %':>13}{'settling ms':>13}{'rms error':>11}{'peak V':>8}  feasible"]  # fmt: skip
    for r in results:
        w = r.worst
        lines.append(
            f"{'*' if r.pareto else ' '}{r.index:>3}  " + "".join(f"{r.settings[a.name]:>19g}" for a in axes)
            + f"{_num(w['overshoot_percent'], '.2f'):>13}{_num(w['settling_time_s'], '.0f', 1e3):>13}"
            f"{_num(w['rms_error'], '.3f'):>11}{_num(w['max_abs_voltage'], '.2f'):>8}  {'yes' if r.feasible else 'no'}"
        )  # fmt: skip
    lines += [f"  #{r.index}: {r.reason}" for r in results if not r.feasible]
    return "\n".join(lines)


def plot_tuning(path: str, method: str, results: Sequence[TuneResult]) -> None:
    """Scatter of settling time (ms) vs overshoot (%), colour = peak voltage (V), Pareto ringed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    shown = [r for r in results if None not in r.worst.values()]
    fig = Figure(figsize=(8, 6), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    x = [r.worst["settling_time_s"] * 1e3 for r in shown]  # type: ignore[operator]
    y = [r.worst["overshoot_percent"] for r in shown]
    points = ax.scatter(x, y, c=[r.worst["max_abs_voltage"] for r in shown], cmap="viridis", s=36)
    fig.colorbar(points, ax=ax, label="peak |voltage| (V)")
    for xi, yi, r in zip(x, y, shown, strict=True):
        if r.pareto:
            ax.scatter([xi], [yi], s=150, facecolors="none", edgecolors="tab:red", linewidths=1.5)
            ax.annotate(
                str(r.index), (xi, yi), xytext=(7, 5), textcoords="offset points", color="tab:red"
            )
    ax.set_xlabel("settling time, 2 % (ms)")
    ax.set_ylabel("overshoot (%)")
    ax.set_title(f"cartctl tune --method {method}: {len(shown)} of {len(results)} settings settled; "
                 "worse of motors a, b; ringed: Pareto front", fontsize=10)  # fmt: skip
    ax.grid(True, color="0.9")
    fig.savefig(path)


def choose(args: argparse.Namespace, result: TuneResult) -> tuple[list[str], int]:
    """Write the chosen setting's controller file with ``cartctl design`` in this process.

    Returns the design arguments used and the design command's exit code. Its report is kept off
    stdout; ``sys.argv`` is set to the design command meanwhile, so the file's ``command`` is the
    design command, exactly as ``cartctl design`` would record it.
    """
    from cartctl.cli import main as cli_main

    if not result.feasible:
        raise InputError(f"--choose {result.index}: that setting is infeasible ({result.reason})")
    argv = ["design", *design_argv(args.model, args.method, result.settings, args.extra_delay),
            "--out", args.out]  # fmt: skip
    saved = sys.argv
    sys.argv = ["cartctl", *argv]
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            code = cli_main(argv)
    finally:
        sys.argv = saved
    return argv, code


def run(args: argparse.Namespace) -> int:
    axes = parse_grid(args.grid, args.method)
    settings = grid_settings(axes)
    _check(args, len(settings))
    job = TuneJob(str(args.model), args.method, args.plant, args.preset, args.reference,
                  float(args.duration), args.extra_delay,
                  tuple(enumerate(settings, start=1)))  # fmt: skip
    results = sort_results(mark_pareto(_run_grid(job, args.jobs or os.cpu_count() or 1)))
    if args.plot:
        plot_tuning(args.plot, args.method, results)
    chosen: dict[str, Any] | None = None
    if args.choose is not None:
        argv, code = choose(args, next(r for r in results if r.index == args.choose))
        if code:
            return code
        chosen = {"index": args.choose, "out": args.out, "command": "cartctl " + shlex.join(argv)}
    if args.json:
        print(json.dumps({"method": args.method, "model": str(args.model), "plant": args.plant,
                          "reference": args.reference, "duration_s": args.duration,
                          "extra_delay_ticks": args.extra_delay, "metrics_of": "worse of motors a and b",
                          "settings": [r.to_dict() for r in results], "chosen": chosen}))  # fmt: skip
        return 0
    front, feasible = sum(r.pareto for r in results), sum(r.feasible for r in results)
    print(f"{args.method} on {args.model}, {args.plant} plant, {args.reference}, {args.duration:g} s: "
          f"{len(results)} settings, {feasible} feasible, {front} on the Pareto front (*); "
          "metrics: the worse of motors a and b")  # fmt: skip
    print(format_table(args.method, results))
    if args.plot:
        print(f"wrote {args.plot}")
    if chosen is not None:
        print(f"wrote {args.out}: {chosen['command']}")
    return 0
