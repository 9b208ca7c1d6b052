"""``cartctl tune MODEL.toml --method pi|poles``: a grid of designs, each run in the simulated loop
(:mod:`cartctl.tune`); the table or JSON, the plot, and ``--choose N --out FILE``, which writes
setting N's controller as ``cartctl design`` does. The refusals are ``tune_checks``'."""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Sequence
from dataclasses import replace
from itertools import groupby
from typing import TYPE_CHECKING, Any

import cartctl.cli.commands.tune_checks as checks
from cartctl.choices import MAX_TUNE_SETTINGS
from cartctl.cli.commands.options import FORMS, MAX_JOBS, check_outputs, seed
from cartctl.cli.commands.validate import check_plot_path
from cartctl.design.request import MAX_EXTRA_DELAY_TICKS, METHODS  # light: no numpy
from cartctl.errors import InputError

if TYPE_CHECKING:  # the tuning modules load numpy and scipy: imported where used, not for --help
    from cartctl.tune import engine
    from cartctl.tune import grid as tuning

_Outcome = tuple[list[Any], list[Any], Callable[[], Any], str, dict[str, Any], list[str]]
"""The rows of ``--json``, the results to choose from, the best of them, the choice rule, the
JSON keys after ``chosen`` and the text lines."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune",
        help="design a grid of controllers, run each in the simulated loop, show the Pareto front",
        description="Design one controller per grid setting (pi: phase margin × crossover; poles: "
        "settling time × overshoot), run each like 'cartctl run --fast' against a simulated plant "
        "with the loop delay the design is for (--extra-delay) and compare overshoot, settling "
        "time (band: 2 % of the step or one encoder count per tick, whichever is wider), RMS "
        "error and peak voltage (the worse of motors a and b). Grid: comma-separated "
        "NAME=START:STOP:STEP (inclusive) or NAME=VALUE, NAME being design's option without its "
        "dashes; pi axes phase-margin (deg, default 50:75:5), crossover-hz (Hz, 2:5:0.5); poles "
        "axes settling-time (s, 0.04:0.16:0.02), overshoot (%, 0.5:5:1.5). The older names "
        "phase_margin, crossover_hz, settling_time are accepted too.",
    )
    p.add_argument("model", metavar="MODEL.toml", help="model to design on (and of the sim plant)")
    p.add_argument("--method", choices=METHODS, required=True)
    p.add_argument("--grid", metavar="SPEC",
                   help="e.g. 'phase-margin=50:75:5,crossover-hz=2:5:0.5' (at most "
                        f"{MAX_TUNE_SETTINGS} settings; each value in the range cartctl design "
                        "takes for its option)")  # fmt: skip
    p.add_argument("--plant", default="sim", metavar="PLANT",
                   help="sim (MODEL, the default), physics or physics:actuation_ms=X (the "
                        "physics --preset with each command landing X ms after its tick, "
                        "0 < X <= 10 to 0.1 ms)")  # fmt: skip
    p.add_argument("--preset", choices=("air", "ground"), default="ground", help="physics preset")
    p.add_argument("--reference", default="step:10", metavar="SPEC",
                   help=f"speed reference of both motors (default step:10): {FORMS}")  # fmt: skip
    p.add_argument("--duration", type=float, default=2.0, metavar="S",
                   help="run time of each setting (default 2 s, at most "
                        f"{checks.MAX_TUNE_DURATION_S:g} s, and at most "
                        f"{checks.MAX_GRID_TICKS:,} ticks over the grid)")  # fmt: skip
    p.add_argument("--extra-delay", type=int, default=0, metavar="N",
                   help="ticks of loop delay beyond the model's, designed for and simulated "
                        f"(a PC-side loop over serial; 0..{MAX_EXTRA_DELAY_TICKS})")  # fmt: skip
    p.add_argument("--jobs", type=int, metavar="N",
                   help=f"worker processes, 1..{MAX_JOBS} (default: all cores)")  # fmt: skip
    p.add_argument("--plot", metavar="FILE.png",
                   help="run settling time vs run overshoot; the front of these two ringed and "
                        "numbered")  # fmt: skip
    p.add_argument("--choose", metavar="N|best",
                   help="write setting #N's controller (with --out); 'best': the lowest "
                        "(worst-case, with --robust) overshoot among the settings that settle "
                        "(on every plant), then the fastest (nominal) settling")  # fmt: skip
    p.add_argument("--robust", action="store_true",
                   help="also score every setting on --plants plants drawn from the model's "
                        "uncertainty (θ ± its theta_std, uniform; DC gain ±10 %%; loop delay ±1 "
                        "tick) and on the physics --preset (also at each --actuation-ms); report "
                        "nominal, worst case, spread and the front of nominal settling against "
                        "worst-case overshoot")  # fmt: skip
    p.add_argument("--plants", type=int, metavar="N",
                   help=f"plants drawn for --robust, 1..{checks.MAX_PLANTS} (default "
                        f"{checks.DEFAULT_PLANTS}; at most {checks.MAX_ROBUST_PLANT_TICKS:,} "
                        "plant-ticks over the grid)")  # fmt: skip
    p.add_argument("--seed", type=seed, metavar="S", help="seed of the plants drawn for --robust (default 1)")  # fmt: skip
    p.add_argument("--actuation-ms", metavar="X,Y,...",
                   help="with --robust: also run every setting on the physics --preset with each "
                        "command landing X ms after its tick (0 < X <= 10, to 0.1 ms; 3: the "
                        "presets' calibrated timing, 10: the next tick's io()), one run per "
                        "timing; these runs enter the worst case and --choose best like the "
                        "sampled plants (default 3,10; 'none': only the physics preset as it is, "
                        "reported beside the worst case)")  # fmt: skip
    p.add_argument("--max-overshoot", type=float, metavar="PERCENT",
                   help="--choose best only among the settings whose overshoot is at most this "
                        "on the plant (with --robust: on the model and on the physics --preset "
                        "at each --actuation-ms)")  # fmt: skip
    p.add_argument("--max-settling", type=float, metavar="S",
                   help="--choose best only among the settings whose settling time is at most "
                        "this (s), where --max-overshoot applies")  # fmt: skip
    p.add_argument("--process-noise-v", type=float, metavar="V",
                   help="the estimator's process noise of every setting, as cartctl design's "
                        "(default: design's)")  # fmt: skip
    p.add_argument("--bias-drift-v", type=float, metavar="V",
                   help="the estimator's disturbance random walk of every setting, as cartctl "
                        "design's (default: design's)")  # fmt: skip
    p.add_argument("--out", metavar="CONTROLLER.toml", help="where --choose writes the controller")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def choosable_text(results: Sequence[tuning.TuneResult]) -> str:
    """The settings ``--choose N`` accepts (those designed and run), as ranges: '5-7, 11-14'."""
    indices = sorted(r.index for r in results if r.feasible)
    if not indices:
        return "none: no setting of the grid could be designed and run; widen the grid"
    # consecutive numbers share their offset from their position: one group, one range
    runs = [[i for _, i in run] for _, run in groupby(enumerate(indices), lambda t: t[1] - t[0])]
    return ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)


def _choose(
    args: argparse.Namespace,
    results: Sequence[tuning.TuneResult],
    best: Callable[[], tuning.TuneResult],
    rule: str,
) -> tuple[dict[str, Any] | None, InputError | None]:
    """``--choose``'s entry and its controller file, written as ``cartctl design`` would, or the
    refusal to raise once the results are printed (a setting that did not run)."""
    from cartctl.tune import engine

    if args.choose is None:
        return None, None
    try:
        result = (
            best() if args.choose == "best" else next(r for r in results if r.index == args.choose)
        )
        if not result.feasible:
            what = ("its run failed" if result.status == "run failed"
                    else "it is an infeasible request: the design refused it")  # fmt: skip
            raise InputError(
                f"--choose {result.index}: setting #{result.index} cannot be chosen, {what} (the "
                f"reason is listed as #{result.index} with the results); settings that can be "
                f"chosen: {choosable_text(results)}"
            )
        fixed = checks.design_fixed(args)
        kind, *parts = args.reference.split(":")
        if kind == "step" and float(parts[0]) != 0.0:  # the file's step: the one tuned on
            fixed["step_rad_s"] = float(parts[0])
        command = engine.save_setting(args.method, result.settings, args.model, args.out,
                                      args.extra_delay, fixed)  # fmt: skip
    except InputError as exc:
        return None, exc
    chosen = {"index": result.index, "out": args.out, "command": command}
    if args.choose == "best":
        chosen["rule"] = rule
    return chosen, None


def _run_grid(args: argparse.Namespace, job: Any, evaluate: Callable[..., Any], label: str) -> Any:
    from cartctl.cli.progress import ProgressBar
    from cartctl.tune import engine

    bar = ProgressBar(len(job.items), label)
    try:
        return engine.run_grid(job, args.jobs or os.cpu_count() or 1, bar.update, evaluate)
    finally:
        bar.close()


def _delay_text(args: argparse.Namespace) -> str:
    return f", {args.extra_delay} extra tick(s) of loop delay" if args.extra_delay else ""


def _nominal(args: argparse.Namespace, job: engine.TuneJob) -> _Outcome:
    """The grid on the plant."""
    from cartctl.tune import choice, engine
    from cartctl.tune import grid as tuning
    from cartctl.tune.plot import plot_tuning

    results = _run_grid(args, job, engine.evaluate_chunk, "cartctl tune")
    results = tuning.sort_results(tuning.mark_pareto(results))
    if args.plot:
        plot_tuning(args.plot, args.method, results)
    limits = checks.choice_limits(args)
    rule = choice.rule_text(choice.CHOICE_RULE_NOMINAL, limits, choice.LIMITS_WHERE_NOMINAL)
    front, plotted = sum(r.pareto for r in results), sum(r.pareto_plot for r in results)
    counts = {k.replace(" ", "_"): v for k, v in tuning.status_counts(results).items()}
    doc = {
        "counts": {"settings": len(results), **counts, "pareto": front, "pareto_plot": plotted},
        "statuses": tuning.STATUSES,
        "pareto_of": list(tuning.METRICS),
        "pareto_plot_of": list(tuning.PLOT_METRICS),
    }
    text = [
        f"{args.method} on {args.model}, {args.plant} plant{_delay_text(args)}, "
        f"{args.reference}, {args.duration:g} s: {choice.counts_text(results)}",
        choice.LEGEND,
        f"*: on the Pareto front over the four run metrics "
        f"({choice.plural(front, 'setting', 'settings')}); o: on the front of run settling "
        f"against run overshoot, the axes of --plot, which rings them "
        f"({choice.plural(plotted, 'setting', 'settings')})",
        choice.format_table(args.method, results),
    ]
    return results, results, lambda: choice.choose_best_nominal(results, limits), rule, doc, text


def _robust(args: argparse.Namespace, job: engine.TuneJob) -> _Outcome:
    """``--robust``: the grid on the nominal model, the sampled plants and the physics preset."""
    from cartctl.data.modelfile import load_models
    from cartctl.tune import choice
    from cartctl.tune import grid as tuning
    from cartctl.tune import robust as robustness
    from cartctl.tune.batch import describe_line, sample_plants
    from cartctl.tune.plot import plot_robust

    plants, timings = args.plants, args.timings
    sample = sample_plants(
        load_models(args.model), plants, args.seed, extra_delay_ticks=args.extra_delay
    )
    rjob = robustness.RobustJob(**vars(job), sample=sample, actuation_ms=timings)
    rows = _run_grid(args, rjob, robustness.evaluate_robust_chunk, "cartctl tune --robust")
    marked = tuning.mark_pareto([r.result for r in rows])  # the plain front, for the JSON rows
    rows = [replace(r, result=m) for r, m in zip(rows, marked, strict=True)]
    rows = choice.sort_robust(choice.mark_robust_pareto(rows))
    if args.plot:
        plot_robust(args.plot, args.method, rows, plants)
    limits = checks.choice_limits(args)
    rule = choice.rule_text(choice.CHOICE_RULE, limits, choice.LIMITS_WHERE)
    timed = ", ".join(f"{ms:g}" for ms in timings)
    landing = f"with commands landing {timed} ms after their tick"
    worst_over = "the nominal model and the sampled plants"
    meta = {
        **sample.describe(),
        "nominal": f"the model ({args.model}), as without --robust",
        "worst_over": worst_over + (f" and the physics preset {landing}" if timings else ""),
        "worst_sampled_over": worst_over,
        "actuation_ms": list(timings),
        "spread_over": "the sampled plants (percentiles: values of sampled plants)",
        "physics_preset": args.preset,
        "pareto_of": "nominal settling_time_s against worst-case overshoot_percent",
        "choice_rule": rule,
        "counts": {k.replace(" ", "_"): v for k, v in choice.robust_counts(rows).items()},
        "statuses": choice.ROBUST_STATUSES,
    }
    if timings:
        legend = (
            f"nominal: the model; worst: over the model, the {plants} plants and physics preset "
            f"{args.preset} {landing} (∞: a plant never settles); p5–p95: over the plants; "
            "physics run, X ms: those runs"
        )
    else:
        legend = (
            f"nominal: the model; worst: over the model and the {plants} plants (∞: a plant never "
            f"settles); p5–p95: over the plants; physics: preset {args.preset}, not in the worst "
            "case"
        )
    text = [
        f"{args.method} on {args.model}{_delay_text(args)}, {args.reference}, "
        f"{args.duration:g} s, --robust: {choice.robust_counts_text(rows)}; the worse of "
        "motors a and b",
        describe_line(sample, str(args.model)),
        legend,
        choice.LEGEND,
        f"*: on the robust Pareto front, nominal settling against worst-case overshoot, the "
        f"axes of --plot, which rings them "
        f"({choice.plural(sum(r.pareto for r in rows), 'setting', 'settings')})",
        choice.format_robust_table(args.method, rows),
    ]

    def best() -> tuning.TuneResult:
        return choice.choose_best_robust(rows, limits).result

    return rows, [r.result for r in rows], best, rule, {"robust": meta}, text


def run(args: argparse.Namespace) -> int:
    checks.check_options(args)  # what sets the size of the work, before anything heavy is imported
    from cartctl.tune import grid as tuning

    settings = tuning.grid_settings(tuning.parse_grid(args.grid, args.method))
    checks.check_work(args, len(settings))
    checks.check_inputs(args, len(settings))
    check_outputs(args, files=("out", "plot"), inputs=(args.model,))
    check_plot_path(args.plot)  # a PNG: matplotlib would refuse another suffix after the work

    from cartctl.cli.jsonout import dumps
    from cartctl.tune import engine

    job = engine.TuneJob(str(args.model), args.method, args.plant, args.preset, args.reference,
                         float(args.duration), args.extra_delay,
                         tuple(enumerate(settings, start=1)),
                         tuple(checks.design_fixed(args).items()))  # fmt: skip
    rows, results, best, rule, doc, text = (_robust if args.robust else _nominal)(args, job)
    chosen, refusal = _choose(args, results, best, rule)
    if args.json:
        head = {
            "method": args.method,
            "model": str(args.model),
            "plant": args.plant,
            "reference": args.reference,
            "duration_s": args.duration,
            "extra_delay_ticks": args.extra_delay,
            "metrics_of": "worse of motors a and b",
        }
        print(dumps({**head, "settings": [r.to_dict() for r in rows], "chosen": chosen, **doc}))
    else:
        print("\n".join(text))
        if args.plot:
            print(f"wrote {args.plot}")
        if chosen is not None:  # the setting's number where the command does not show it
            which = f" (setting #{chosen['index']})" if args.robust or "rule" in chosen else ""
            print(f"wrote {args.out}{which}: {chosen['command']}")
    if refusal is not None:
        raise refusal
    return 0
