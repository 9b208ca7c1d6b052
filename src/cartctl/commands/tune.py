"""``cartctl tune MODEL.toml --method pi|poles``: a grid of designs, each run in the simulated loop.

Between ``design`` and ``run``. The grid and the Pareto front are :mod:`cartctl.tune.grid`;
designing and running the settings on worker processes is :mod:`cartctl.tune.engine`. Here: the
options, the table or JSON, the plot, and ``--choose N --out FILE``, which writes setting N's
controller file through ``cartctl design`` itself.

Each setting is scored on the loop it is designed for: with ``--extra-delay N`` the simulated
plant has N more ticks of delay too. Settling is measured in the band of ``cartctl design``'s
settling bound, max(2 %, one encoder count per tick).

``--robust`` (:mod:`cartctl.tune.robust`) also scores every setting on ``--plants N`` plants drawn
from the model's uncertainty (:mod:`cartctl.tune.uncertainty`, ``--seed``), simulated all at once
(:mod:`cartctl.tune.batch`), and on the physics preset; the table, ``--json`` (key ``robust``,
added to each row and at the top) and the plot then show nominal, worst case, spread and physics,
and the front of nominal settling against worst-case overshoot. ``--choose best`` picks by
:data:`cartctl.tune.robust_choice.CHOICE_RULE` (with ``--robust``) or
:data:`~cartctl.tune.robust_choice.CHOICE_RULE_NOMINAL` (without).
"""

from __future__ import annotations

import argparse
import os
import shlex
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cartctl.cart import PERIOD_S
from cartctl.commands.options import FORMS, check_duration
from cartctl.design.request import METHODS  # light; tune.grid.AXES has one entry per method
from cartctl.errors import InputError

if TYPE_CHECKING:  # the tuning modules load numpy and scipy: imported where used, not for --help
    from cartctl.tune import engine
    from cartctl.tune import grid as tuning
    from cartctl.tune import robust as robustness


DEFAULT_PLANTS = 200
"""Sampled plants of ``--robust`` by default."""

MAX_PLANTS = 10_000
"""The most ``--plants`` accepted."""

MAX_PLANT_TICKS = 2_000_000
"""(plants + 1) × ticks per motor beyond which ``--robust`` is refused (memory: four float64
arrays of that size per motor in each worker, 64 MB each)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune",
        help="design a grid of controllers, run each in the simulated loop, show the Pareto front",
        description=(
            "Design one controller per grid setting (pi: phase margin × crossover; poles: settling "
            "time × overshoot), run each like 'cartctl run --fast' against a simulated plant with "
            "the loop delay the design is for (--extra-delay) and compare overshoot, settling time "
            "(band: 2 %% of the step or one encoder count per tick, whichever is wider), RMS error "
            "and peak voltage (the worse of motors a and b). Grid: comma-separated "
            "NAME=START:STOP:STEP (inclusive) or NAME=VALUE; pi "
            "axes phase_margin (deg, default 50:75:5), crossover_hz (Hz, 2:5:0.5); poles axes "
            "settling_time (s, 0.04:0.16:0.02), overshoot (%, 0.5:5:1.5)."
        ),
    )
    p.add_argument("model", metavar="MODEL.toml", help="model to design on (and of the sim plant)")
    p.add_argument("--method", choices=METHODS, required=True)
    p.add_argument("--grid", metavar="SPEC", help="e.g. 'phase_margin=50:75:5,crossover_hz=2:5:0.5'")  # fmt: skip
    p.add_argument("--plant", default="sim", choices=("sim", "physics"), help="default sim (MODEL)")
    p.add_argument("--preset", choices=("air", "ground"), default="ground", help="physics preset")
    p.add_argument("--reference", default="step:10", metavar="SPEC",
                   help=f"speed reference of both motors (default step:10): {FORMS}")  # fmt: skip
    p.add_argument("--duration", type=float, default=2.0, metavar="S", help="run time (default 2 s)")  # fmt: skip
    p.add_argument("--extra-delay", type=int, default=0, metavar="N",
                   help="ticks of loop delay beyond the model's, designed for and simulated "
                        "(a PC-side loop over serial)")  # fmt: skip
    p.add_argument("--jobs", type=int, metavar="N", help="worker processes (default: all cores)")
    p.add_argument("--plot", metavar="FILE.png", help="settling time vs overshoot scatter")
    p.add_argument("--choose", metavar="N|best",
                   help="write setting #N's controller (with --out); 'best': the lowest "
                        "(worst-case, with --robust) overshoot among the settings that settle "
                        "(on every plant), then the fastest (nominal) settling")  # fmt: skip
    p.add_argument("--robust", action="store_true",
                   help="also score every setting on --plants plants drawn from the model's "
                        "uncertainty (θ ± its theta_std, uniform; DC gain ±10 %%; loop delay ±1 "
                        "tick) and on the physics --preset; report nominal, worst case, spread "
                        "and the front of nominal settling against worst-case overshoot")  # fmt: skip
    p.add_argument("--plants", type=int, metavar="N",
                   help=f"plants drawn for --robust (default {DEFAULT_PLANTS})")  # fmt: skip
    p.add_argument("--seed", type=int, metavar="S", help="seed of the plants drawn for --robust (default 1)")  # fmt: skip
    p.add_argument("--out", metavar="CONTROLLER.toml", help="where --choose writes the controller")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _choice(text: str | None, n_settings: int) -> int | str | None:
    """``--choose``: None, 'best', or a setting number in 1..n_settings."""
    if text is None or text.strip() == "best":
        return None if text is None else "best"
    try:
        number = int(text)
    except ValueError:
        raise InputError(f"--choose takes a setting number or 'best', got '{text}'") from None
    if not 1 <= number <= n_settings:
        raise InputError(f"--choose must be a setting number in 1..{n_settings}, got {number}")
    return number


def _check_robust(args: argparse.Namespace) -> None:
    if not args.robust:
        given = [o for o, v in (("--plants", args.plants), ("--seed", args.seed)) if v is not None]
        if given:
            raise InputError(f"{' and '.join(given)} only apply to --robust")
        return
    if args.plant != "sim":
        raise InputError("--robust scores on the model (sim) and the physics --preset; leave out "
                         "--plant physics")  # fmt: skip
    plants = DEFAULT_PLANTS if args.plants is None else args.plants
    if not 1 <= plants <= MAX_PLANTS:
        raise InputError(f"--plants must be a number of plants in 1..{MAX_PLANTS}, got {plants}")
    ticks = max(1, round(args.duration / PERIOD_S))
    if (plants + 1) * ticks > MAX_PLANT_TICKS:
        raise InputError(
            f"--robust with {plants} plants and --duration {args.duration:g} s simulates "
            f"{(plants + 1) * ticks} plant-ticks per motor, more than {MAX_PLANT_TICKS}; use fewer "
            "--plants or a shorter --duration"
        )


def _check(args: argparse.Namespace, n_settings: int) -> None:
    from cartctl.modelfile import load_models
    from cartctl.plants.factory import make_plant
    from cartctl.reference import reference_signal

    check_duration(args.duration)
    _check_robust(args)
    if args.extra_delay < 0:
        raise InputError(f"--extra-delay must be >= 0 ticks, got {args.extra_delay}")
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs must be a number of processes >= 1, got {args.jobs}")
    if (args.choose is None) != (args.out is None):
        raise InputError("--choose N and --out CONTROLLER.toml go together; give both or neither")
    args.choose = _choice(args.choose, n_settings)
    models = load_models(args.model)
    plant, _ = make_plant(args.plant, model_path=args.model, preset=args.preset)
    plant.close()
    if abs(plant.period_s - models.period_s) > 1e-9:
        raise InputError(
            f"the model is for Ts = {models.period_s} s but the plant ticks at {plant.period_s} s"
        )
    reference_signal(args.reference, 1, plant.period_s)  # a bad spec fails here, once


def plot_tuning(path: str, method: str, results: Sequence[tuning.TuneResult]) -> None:
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
    front = sorted((xi, yi, r.index) for xi, yi, r in zip(x, y, shown, strict=True) if r.pareto)
    for n, (xi, yi, index) in enumerate(front):  # labels alternately above and below
        ax.scatter([xi], [yi], s=150, facecolors="none", edgecolors="tab:red", linewidths=1.5)
        ax.annotate(str(index), (xi, yi), xytext=(6, 6 if n % 2 == 0 else -14),
                    textcoords="offset points", color="tab:red", fontsize=9)  # fmt: skip
    ax.set_xlabel("settling time, band max(2 %, one encoder count) (ms)")
    ax.set_ylabel("overshoot (%)")
    ax.set_title(f"cartctl tune --method {method}: {len(shown)} of {len(results)} settings settled; "
                 "worse of motors a, b; ringed: Pareto front", fontsize=10)  # fmt: skip
    ax.grid(True, color="0.9")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)


def plot_robust(path: str, method: str, rows: Sequence[robustness.RobustRow], plants: int) -> None:
    """Nominal settling (ms) against overshoot (%): worst case (colour: p95 settling), nominal
    (grey, joined to it) and physics (x); the robust Pareto front ringed and numbered."""
    import numpy as np
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    shown = []
    for r in rows:
        s = r.score
        if s is None:
            continue
        x = s.value("settling_time_s", "nominal")
        y = s.value("overshoot_percent", "worst")
        if np.isfinite(x) and np.isfinite(y):
            shown.append((x * 1e3, y, s, r))
    fig = Figure(figsize=(8, 6), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for x, y, s, _ in shown:
        ax.plot([x, x], [s.value("overshoot_percent", "nominal"), y], color="0.8", lw=1, zorder=1)
    xs = [x for x, *_ in shown]
    p95 = [s.value("settling_time_s", "p95") * 1e3 for *_, s, _ in shown]
    worst = ax.scatter(xs, [y for _, y, *_ in shown], s=36, zorder=3, plotnonfinite=True,
                       cmap=colormaps["viridis"].with_extremes(bad="black"),
                       c=[v if np.isfinite(v) else np.nan for v in p95],
                       label=f"worst case over the model and {plants} sampled plants")  # fmt: skip
    fig.colorbar(worst, ax=ax, label="settling time, 95th percentile of the plants (ms); "
                 "black: more than 5 % never settle")  # fmt: skip
    ax.scatter(xs, [s.value("overshoot_percent", "nominal") for *_, s, _ in shown], s=12,
               color="0.5", zorder=2, label="nominal (the model)")  # fmt: skip
    phys = [(x, s.physics.get("overshoot_percent")) for x, _, s, _ in shown]
    ax.scatter([x for x, v in phys if v is not None], [v for _, v in phys if v is not None],
               marker="x", color="tab:orange", s=30, zorder=2,
               label=f"physics preset {shown[0][2].physics.get('preset') if shown else ''}")  # fmt: skip
    front = sorted((x, y, r.index) for x, y, _, r in shown if r.pareto)
    for n, (x, y, index) in enumerate(front):
        ax.scatter(
            [x], [y], s=150, facecolors="none", edgecolors="tab:red", linewidths=1.5, zorder=4
        )
        ax.annotate(str(index), (x, y), xytext=(6, 6 if n % 2 == 0 else -14),
                    textcoords="offset points", color="tab:red", fontsize=9)  # fmt: skip
    ax.set_xlabel("nominal settling time, band max(2 %, one encoder count) (ms)")
    ax.set_ylabel("overshoot (%)")
    ax.set_title(f"cartctl tune --method {method} --robust: {len(shown)} of {len(rows)} settings, "
                 "worse of motors a, b;\nringed: Pareto front of nominal settling against worst-case "
                 "overshoot", fontsize=10)  # fmt: skip
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, color="0.9")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)


def choose(args: argparse.Namespace, result: tuning.TuneResult) -> str:
    """Write the chosen setting's controller file, as ``cartctl design`` would.

    Returns the design command (``cartctl design ...``), as the file records it.
    """
    from cartctl.design.controllerfile import save_controller
    from cartctl.design.make import controller_file, design_models
    from cartctl.modelfile import load_models
    from cartctl.tune import grid as tuning

    if not result.feasible:
        raise InputError(f"--choose {result.index}: that setting is infeasible ({result.reason})")
    request = tuning.design_request(args.method, result.settings, args.extra_delay)
    argv = ["design", *request.to_argv(str(args.model), always=tuning.request_axes(args.method)),
            "--out", args.out]  # fmt: skip
    models = load_models(args.model)
    designs = design_models(request, models, ("a", "b"))
    command = "cartctl " + shlex.join(argv)
    save_controller(controller_file(designs, args.model, command=command,
                                    period_s=models.period_s), args.out)  # fmt: skip
    return command


def _chosen(args: argparse.Namespace, result: tuning.TuneResult, rule: str | None) -> dict[str, Any]:  # fmt: skip
    command = choose(args, result)
    out: dict[str, Any] = {"index": result.index, "out": args.out, "command": command}
    if rule is not None:
        out["rule"] = rule
    return out


def run_robust(args: argparse.Namespace, job: engine.TuneJob) -> int:
    """``tune --robust``: the grid on the nominal model, the sampled plants and the physics preset."""
    from cartctl.jsonout import dumps
    from cartctl.modelfile import load_models
    from cartctl.progress import ProgressBar
    from cartctl.tune import engine
    from cartctl.tune import grid as tuning
    from cartctl.tune import robust as robustness
    from cartctl.tune import robust_choice as choice
    from cartctl.tune.uncertainty import describe_line, sample_plants

    plants = DEFAULT_PLANTS if args.plants is None else args.plants
    seed = 1 if args.seed is None else args.seed
    sample = sample_plants(load_models(args.model), plants, seed,
                           extra_delay_ticks=args.extra_delay)  # fmt: skip
    rjob = robustness.RobustJob(job, sample, job.items)
    bar = ProgressBar(len(job.items), "cartctl tune --robust")
    try:
        rows = engine.run_grid(rjob, args.jobs or os.cpu_count() or 1, bar.update,
                               robustness.evaluate_robust_chunk)  # fmt: skip
    finally:
        bar.close()
    marked = tuning.mark_pareto([r.result for r in rows])  # the plain front, for the JSON rows
    rows = [replace(r, result=m) for r, m in zip(rows, marked, strict=True)]
    rows = choice.sort_robust(choice.mark_robust_pareto(rows))
    if args.plot:
        plot_robust(args.plot, args.method, rows, plants)
    chosen: dict[str, Any] | None = None
    if args.choose == "best":
        best = choice.choose_best_robust(rows)
        chosen = _chosen(args, best.result, choice.CHOICE_RULE)
    elif args.choose is not None:
        chosen = _chosen(args, next(r.result for r in rows if r.index == args.choose), None)
    meta = {**sample.describe(), "nominal": f"the model ({args.model}), as without --robust",
            "worst_over": "the nominal model and the sampled plants",
            "spread_over": "the sampled plants (percentiles: values of sampled plants)",
            "physics_preset": args.preset, "pareto_of": "nominal settling_time_s against worst-case "
            "overshoot_percent", "choice_rule": choice.CHOICE_RULE}  # fmt: skip
    if args.json:
        print(dumps({"method": args.method, "model": str(args.model), "plant": args.plant,
                     "reference": args.reference, "duration_s": args.duration,
                     "extra_delay_ticks": args.extra_delay, "metrics_of": "worse of motors a and b",
                     "settings": [r.to_dict() for r in rows], "chosen": chosen,
                     "robust": meta}))  # fmt: skip
        return 0
    front = sum(r.pareto for r in rows)
    feasible = sum(r.score is not None for r in rows)
    delay = f", {args.extra_delay} extra tick(s) of loop delay" if args.extra_delay else ""
    print(f"{args.method} on {args.model}{delay}, {args.reference}, {args.duration:g} s, --robust: "
          f"{len(rows)} settings, {feasible} feasible, {front} on the robust Pareto front (*: "
          "nominal settling vs worst-case overshoot); the worse of motors a and b")  # fmt: skip
    print(describe_line(sample, str(args.model)))
    print(f"nominal: the model; worst: over the model and the {plants} plants (∞: a plant never "
          f"settles); p5–p95: over the plants; physics: preset {args.preset}, not in the worst "
          "case")  # fmt: skip
    print(choice.format_robust_table(args.method, rows))
    if args.plot:
        print(f"wrote {args.plot}")
    if chosen is not None:
        print(f"wrote {args.out} (setting #{chosen['index']}): {chosen['command']}")
    return 0


def run(args: argparse.Namespace) -> int:
    from cartctl.jsonout import dumps
    from cartctl.progress import ProgressBar
    from cartctl.tune import engine
    from cartctl.tune import grid as tuning
    from cartctl.tune import robust_choice as choice

    axes = tuning.parse_grid(args.grid, args.method)
    settings = tuning.grid_settings(axes)
    _check(args, len(settings))
    job = engine.TuneJob(str(args.model), args.method, args.plant, args.preset, args.reference,
                         float(args.duration), args.extra_delay,
                         tuple(enumerate(settings, start=1)))  # fmt: skip
    if args.robust:
        return run_robust(args, job)
    bar = ProgressBar(len(settings), "cartctl tune")
    try:
        results = engine.run_grid(job, args.jobs or os.cpu_count() or 1, bar.update)
    finally:
        bar.close()
    results = tuning.sort_results(tuning.mark_pareto(results))
    if args.plot:
        plot_tuning(args.plot, args.method, results)
    chosen: dict[str, Any] | None = None
    if args.choose == "best":
        chosen = _chosen(args, choice.choose_best_nominal(results),
                         choice.CHOICE_RULE_NOMINAL)  # fmt: skip
    elif args.choose is not None:
        chosen = _chosen(args, next(r for r in results if r.index == args.choose), None)
    if args.json:
        print(dumps({"method": args.method, "model": str(args.model), "plant": args.plant,
                          "reference": args.reference, "duration_s": args.duration,
                          "extra_delay_ticks": args.extra_delay, "metrics_of": "worse of motors a and b",
                          "settings": [r.to_dict() for r in results], "chosen": chosen}))  # fmt: skip
        return 0
    front, feasible = sum(r.pareto for r in results), sum(r.feasible for r in results)
    delay = f", {args.extra_delay} extra tick(s) of loop delay" if args.extra_delay else ""
    print(f"{args.method} on {args.model}, {args.plant} plant{delay}, {args.reference}, {args.duration:g} s: "
          f"{len(results)} settings, {feasible} feasible, {front} on the Pareto front (*); "
          "metrics: the worse of motors a and b")  # fmt: skip
    print(tuning.format_table(args.method, results))
    if args.plot:
        print(f"wrote {args.plot}")
    if chosen is not None:
        which = f" (setting #{chosen['index']})" if "rule" in chosen else ""
        print(f"wrote {args.out}{which}: {chosen['command']}")
    return 0
