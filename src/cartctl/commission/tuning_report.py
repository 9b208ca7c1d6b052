"""The tuning and verification sections of commissioning's summary, and the tuning's step figure."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.commission import tuning, verify
from cartctl.commission.report import fmt, plot_lines, table
from cartctl.model import ArxModel


def tuning_body(result: tuning.TuningResult, command: str) -> str:
    """The tuning section: the rule, the grid's table (worse of motors a and b), the choice."""
    rows = []
    for row in result.rows:
        r = tuning.row_summary(row)
        s = r["settings"]
        mark = "**→**" if row.index == result.chosen.index else ("*" if r.get("pareto") else "")
        if "nominal" not in r:
            rows.append([mark, str(r["index"]), f"{s['settling-time'] * 1e3:g}",
                         f"{s['overshoot']:g}", r["status"], "", "", "", "", ""])  # fmt: skip
            continue
        nom, worst = r["nominal"], r["worst"]
        timing = " / ".join(fmt(e["overshoot_percent"], 1) for e in r["timing"])
        rows.append([mark, str(r["index"]), f"{s['settling-time'] * 1e3:g}", f"{s['overshoot']:g}",
                     fmt(nom["overshoot_percent"], 1), fmt(nom["settling_time_s"], 0, 1e3),
                     fmt(worst["overshoot_percent"], 1), fmt(worst["settling_time_s"], 0, 1e3),
                     timing, fmt(nom["peak_voltage_v"], 1)])  # fmt: skip
    later = " and ".join(f"{f * 10:g} ms" for f in tuning.LATER_FRACTIONS)
    return (
        f"Pole placement with a Kalman estimator, designed for a loop delay of "
        f"{result.design_fixed['loop_delay_ticks']} tick(s); each setting run in the simulated "
        f"loop ({tuning.REFERENCE}, {tuning.DURATION_S:g} s) on the model (nominal), on "
        f"{tuning.PLANTS} plants drawn from its uncertainty (θ ± its standard deviation, DC gain "
        f"±10 %, loop delay −1/0/+1 tick; worst = over them, the model and the timing plants) "
        f"and on the model with each command landing {later} later (timing plants).\n\n"
        f"Choice: among the settings that settle on every plant, with overshoot ≤ "
        f"{tuning.MAX_OVERSHOOT_PERCENT:g} % on the model and on the timing plants and nominal "
        f"settling ≤ {tuning.MAX_SETTLING_S * 1e3:g} ms, the lowest worst-case overshoot, then "
        f"the fastest nominal settling (`tune --robust --choose best`'s rule).\n\n"
        + table(
            [
                "",
                "#",
                "settling target (ms)",
                "overshoot target (%)",
                "nominal overshoot (%)",
                "nominal settling (ms)",
                "worst overshoot (%)",
                "worst settling (ms)",
                f"timing plants overshoot (%) ({later})",
                "peak voltage (V)",
            ],
            rows,
        )
        + f"\n\n→ chosen; *: on the robust Pareto front. Controller: `{command}`.\n\n"
        + "".join(f"Setting #{i} passed over: {why}.\n\n" for i, why in result.refused)
        + "Files: controller.toml, tuning.rrd, tuning.png."
    )


def tuning_steps(controller_path: Path, model_path: Path,
                 later: Callable[[ArxModel, float], ArxModel],
                 png: Path) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:  # fmt: skip
    """The chosen controller's simulated step on the model and the timing plants (series, PNG)."""
    from cartctl.data.modelfile import load_models
    from cartctl.design.build import build_controllers
    from cartctl.design.controllerfile import load_controller
    from cartctl.plants.sim import ArxPlant
    from cartctl.reference import reference_signal
    from cartctl.runtime.fast import run_in_memory

    file = load_controller(controller_path)
    models = load_models(model_path)
    n = round(tuning.DURATION_S / models.period_s)
    plants = {"model": [models.motor(m) for m in "ab"]}
    for f in tuning.LATER_FRACTIONS:
        plants[f"{f * 10:g} ms later"] = [later(models.motor(m), f) for m in "ab"]
    series: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    speed, volts = {}, {}
    for name, (a, b) in plants.items():
        refs = {m: reference_signal(tuning.REFERENCE, n, models.period_s, m) for m in "ab"}
        columns, _ = run_in_memory(ArxPlant(a, b), build_controllers(file), refs,
                                   period_s=models.period_s,
                                   voltage_limit_v=file.voltage_limit_v)  # fmt: skip
        t = columns["time_s"]
        key = name.replace(" ", "_")
        for m in "ab":
            series[f"tuning/{key}/speed_{m}"] = (t, columns[f"speed_{m}"])
            series[f"tuning/{key}/voltage_{m}"] = (t, columns[f"voltage_{m}"])
        speed[f"motor a, {name}"] = (t, columns["speed_a"])
        volts[f"motor a, {name}"] = (t, columns["voltage_a"])
        series["tuning/reference"] = (t, columns["reference_a"])
    plot_lines(png, "The chosen controller's simulated step", [
        ("speed (rad/s)", speed), ("voltage (V)", volts)])  # fmt: skip
    return series


def verification_body(checked: verify.Verification, summary: dict[str, Any],
                      argv: list[str]) -> str:  # fmt: skip
    """The verification section: measured against predicted, the bounds, pass or fail."""
    m, p, lim = checked.measured, checked.predicted, checked.limits
    rows = [
        ["overshoot (%)", fmt(m["overshoot_percent"], 2), fmt(p.get("nominal_overshoot_percent"), 2),
         fmt(p.get("worst_overshoot_percent"), 2), f"≤ {lim['overshoot_percent']:.2f}"],
        ["settling (ms)", fmt(m["settling_time_s"], 0, 1e3),
         fmt(p.get("nominal_settling_time_s"), 0, 1e3), fmt(p.get("worst_settling_time_s"), 0, 1e3),
         f"≤ {lim['settling_time_s'] * 1e3:.0f}"],
    ]  # fmt: skip
    return (
        f"`cartctl {' '.join(argv)}` (worse of motors a and b, on the {lim['speed']} speed).\n\n"
        + table(["", "measured", "predicted nominal", "predicted worst", "pass bound"], rows)
        + f"\n\n**{'PASS' if checked.passed else 'FAIL'}**. Bounds: overshoot ≤ max("
        f"{verify.TARGET_OVERSHOOT_PERCENT:g} %, predicted nominal) + a tolerance "
        f"({verify.TRUE_SPEED_TOLERANCE_PP:g} point on a true speed, half an encoder count per "
        "tick over the step more on the smoothed speed, a whole count on the bare encoder "
        f"speed); settling ≤ max({verify.TARGET_SETTLING_S * 1e3:g} ms, "
        "predicted nominal + 20 ms). The prediction is the linear model's: a cart's friction "
        "and encoder, which the model leaves out, usually add a point or two of overshoot; the "
        "bounds are the targets, the prediction is shown beside them.\n\n"
        f"Files: {Path(str(summary.get('trace'))).name}, "
        f"{Path(str(summary.get('recording'))).name}."
    )
