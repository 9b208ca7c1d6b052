"""``cartctl tune --robust``, after the scoring: the robust Pareto front, the choice, the table.

The rows come from :func:`cartctl.tune.robust.evaluate_robust_chunk`. The front is over (nominal
settling time, worst-case overshoot), both minimised, among the feasible settings where both are
finite; :func:`choose_best_robust` and :func:`choose_best_nominal` apply :data:`CHOICE_RULE` and
:data:`CHOICE_RULE_NOMINAL`; the terminal table is :func:`cartctl.tune.table.format_robust_table`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from cartctl.errors import InputError
from cartctl.tune.grid import TuneResult, pareto_front
from cartctl.tune.robust import RobustRow

CHOICE_RESOLUTION_PERCENT = 0.01
"""Overshoots that round to the same multiple of this (%) tie in ``--choose best``."""

CHOICE_RULE = (
    "lowest worst-case overshoot (to 0.01 %) among the feasible settings that settle on every "
    "plant (the model, the sampled plants and the physics preset at each --actuation-ms), then "
    "the fastest nominal settling, then the lowest index"
)
CHOICE_RULE_NOMINAL = (
    "lowest overshoot (to 0.01 %) among the feasible settings that settle, then the fastest "
    "settling, then the lowest index (worse of motors a and b)"
)


def mark_robust_pareto(rows: Sequence[RobustRow]) -> list[RobustRow]:
    """The rows with ``pareto`` set: non-dominated in (nominal settling, worst-case overshoot)."""
    points = []
    for r in rows:
        if r.score is None:
            points.append([math.nan, math.nan])
            continue
        x = r.score.value("settling_time_s", "nominal")
        y = r.score.value("overshoot_percent", "worst")
        points.append([x if math.isfinite(x) else math.nan, y if math.isfinite(y) else math.nan])
    front = pareto_front(np.reshape(points, (len(rows), 2)))
    return [replace(r, pareto=bool(f)) for r, f in zip(rows, front, strict=True)]


def _rounded(overshoot: float) -> float:
    return round(overshoot / CHOICE_RESOLUTION_PERCENT)


def choose_best_robust(rows: Sequence[RobustRow]) -> RobustRow:
    """The setting ``--choose best`` takes with ``--robust`` (:data:`CHOICE_RULE`).

    Raises
    ------
    InputError
        No feasible setting settles on every plant.
    """
    candidates = [r for r in rows if r.score is not None and r.score.settles_everywhere
                  and math.isfinite(r.score.value("overshoot_percent", "worst"))]  # fmt: skip
    if not candidates:
        raise InputError("--choose best: no feasible setting settles on every sampled plant "
                         "and physics run; widen the grid or pick one with --choose N")  # fmt: skip

    def key(r: RobustRow) -> tuple[float, float, int]:
        assert r.score is not None
        settling = r.score.value("settling_time_s", "nominal")
        return (_rounded(r.score.value("overshoot_percent", "worst")),
                settling if math.isfinite(settling) else math.inf, r.index)  # fmt: skip

    return min(candidates, key=key)


def choose_best_nominal(results: Sequence[TuneResult]) -> TuneResult:
    """The setting ``--choose best`` takes without ``--robust`` (:data:`CHOICE_RULE_NOMINAL`).

    Raises
    ------
    InputError
        No feasible setting settles.
    """
    candidates = [r for r in results if r.feasible and r.worst["settling_time_s"] is not None
                  and r.worst["overshoot_percent"] is not None]  # fmt: skip
    if not candidates:
        raise InputError("--choose best: no feasible setting settles; widen the grid or pick one "
                         "with --choose N")  # fmt: skip
    return min(candidates, key=lambda r: (_rounded(r.worst["overshoot_percent"]),  # type: ignore[arg-type]
                                          r.worst["settling_time_s"], r.index))  # fmt: skip


def sort_robust(rows: Sequence[RobustRow]) -> list[RobustRow]:
    """Robust front first (by nominal settling), then the other scored settings by worst-case
    overshoot, then the infeasible (by index)."""

    def key(r: RobustRow) -> tuple[int, float, float, int]:
        if r.score is None:
            return (3, 0.0, 0.0, r.index)
        settling = r.score.value("settling_time_s", "nominal")
        worst = r.score.value("overshoot_percent", "worst")
        settling = settling if not math.isnan(settling) else math.inf
        worst = worst if not math.isnan(worst) else math.inf
        if r.pareto:
            return (0, settling, worst, r.index)
        return (1, worst, settling, r.index)

    return sorted(rows, key=key)
