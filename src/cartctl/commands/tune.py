"""``cartctl tune MODEL.toml --method pi|poles``: a grid of designs, each run in the simulated loop.

Between ``design`` and ``run``. The grid and the Pareto front are :mod:`cartctl.tune.grid`;
designing and running the settings on worker processes is :mod:`cartctl.tune.engine`. Here: the
options, the table or JSON, the plot, and ``--choose N --out FILE``, which writes setting N's
controller file through ``cartctl design`` itself.

Each setting is scored on the loop it is designed for: with ``--extra-delay N`` the simulated
plant has N more ticks of delay too. Settling is measured in the band of ``cartctl design``'s
settling bound, max(2 %, one encoder count per tick).
"""

from __future__ import annotations

import argparse
import os
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cartctl.commands.options import check_duration
from cartctl.design.controllerfile import save_controller
from cartctl.design.make import controller_file, design_models
from cartctl.errors import InputError
from cartctl.jsonout import dumps
from cartctl.modelfile import load_models
from cartctl.plants.factory import make_plant
from cartctl.progress import ProgressBar
from cartctl.reference import FORMS, reference_signal
from cartctl.tune import engine
from cartctl.tune import grid as tuning


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
    p.add_argument("--method", choices=tuple(tuning.AXES), required=True)
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
    p.add_argument("--choose", type=int, metavar="N", help="write setting #N's controller (with --out)")  # fmt: skip
    p.add_argument("--out", metavar="CONTROLLER.toml", help="where --choose writes the controller")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace, n_settings: int) -> None:
    check_duration(args.duration)
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


def choose(args: argparse.Namespace, result: tuning.TuneResult) -> str:
    """Write the chosen setting's controller file, as ``cartctl design`` would.

    Returns the design command (``cartctl design ...``), as the file records it.
    """
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


def run(args: argparse.Namespace) -> int:
    axes = tuning.parse_grid(args.grid, args.method)
    settings = tuning.grid_settings(axes)
    _check(args, len(settings))
    job = engine.TuneJob(str(args.model), args.method, args.plant, args.preset, args.reference,
                         float(args.duration), args.extra_delay,
                         tuple(enumerate(settings, start=1)))  # fmt: skip
    bar = ProgressBar(len(settings), "cartctl tune")
    try:
        results = engine.run_grid(job, args.jobs or os.cpu_count() or 1, bar.update)
    finally:
        bar.close()
    results = tuning.sort_results(tuning.mark_pareto(results))
    if args.plot:
        plot_tuning(args.plot, args.method, results)
    chosen: dict[str, Any] | None = None
    if args.choose is not None:
        command = choose(args, next(r for r in results if r.index == args.choose))
        chosen = {"index": args.choose, "out": args.out, "command": command}
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
        print(f"wrote {args.out}: {chosen['command']}")
    return 0
