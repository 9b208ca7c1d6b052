"""``cartctl tune --robust`` after the scoring: the robust Pareto front (nominal settling against
worst-case overshoot, both minimised, among feasible settings where both are finite), the
``--choose best`` rules (:data:`CHOICE_RULE`, :data:`CHOICE_RULE_NOMINAL`) and the row order."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from cartctl.errors import InputError
from cartctl.tune.grid import TuneResult, pareto_front
from cartctl.tune.robust import RobustRow

CHOICE_RESOLUTION_PERCENT = 0.01  # overshoots equal to this (the table's resolution) tie

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
    points = np.array([[math.nan, math.nan] if r.score is None
                       else [r.score.value("settling_time_s", "nominal"),
                             r.score.value("overshoot_percent", "worst")]
                       for r in rows]).reshape(len(rows), 2)  # fmt: skip
    front = pareto_front(np.where(np.isfinite(points), points, np.nan))
    return [replace(r, pareto=bool(f)) for r, f in zip(rows, front, strict=True)]


@dataclass(frozen=True)
class Limits:
    """``--max-overshoot`` (%) and ``--max-settling`` (s), None: no bound. ``--choose best`` applies
    them to the nominal run and (with ``--robust``) the physics runs at every actuation timing, not
    to the sampled plants (whose worst case ranks the settings)."""

    overshoot_percent: float | None = None
    settling_time_s: float | None = None

    def __bool__(self) -> bool:
        return self.overshoot_percent is not None or self.settling_time_s is not None

    def text(self) -> str:
        """'overshoot <= 5 %, settling <= 120 ms' (the bounds given)."""
        parts = []
        if self.overshoot_percent is not None:
            parts.append(f"overshoot <= {self.overshoot_percent:g} %")
        if self.settling_time_s is not None:
            parts.append(f"settling <= {self.settling_time_s * 1e3:g} ms")
        return ", ".join(parts)

    def met(self, figures: Sequence[tuple[float | None, float | None]]) -> bool:
        """Every (overshoot %, settling s) within the bounds (None: not met where bounded)."""
        for overshoot, settling in figures:
            bounds = ((overshoot, self.overshoot_percent), (settling, self.settling_time_s))
            for value, bound in bounds:
                if bound is not None and (value is None or not value <= bound):
                    return False
        return True


def rule_text(rule: str, limits: Limits, where: str) -> str:
    """``rule`` with the bounds of ``limits`` (where they apply) in front of it."""
    if not limits:
        return rule
    return f"among the settings with {limits.text()} {where}: {rule}"


LIMITS_WHERE = "on the model and on the physics preset at each --actuation-ms"
LIMITS_WHERE_NOMINAL = "on the plant (worse of motors a and b)"


def _rounded(overshoot: float) -> float:
    return round(overshoot / CHOICE_RESOLUTION_PERCENT)


def _bounded_figures(r: RobustRow) -> list[tuple[float | None, float | None]]:
    assert r.score is not None
    nominal = r.score.figures
    figures = [(nominal["overshoot_percent"]["nominal"], nominal["settling_time_s"]["nominal"])]
    figures += [(e.get("overshoot_percent"), e.get("settling_time_s")) for e in r.score.actuation]
    return figures


def choose_best_robust(rows: Sequence[RobustRow], limits: Limits = Limits()) -> RobustRow:
    """``--choose best`` with ``--robust`` (:data:`CHOICE_RULE`), within ``limits``; InputError when
    no setting qualifies."""
    candidates = [r for r in rows if r.score is not None and r.score.settles_everywhere
                  and math.isfinite(r.score.value("overshoot_percent", "worst"))]  # fmt: skip
    if not candidates:
        raise InputError("--choose best: no feasible setting settles on every sampled plant "
                         "and physics run; widen the grid or pick one with --choose N")  # fmt: skip
    candidates = [r for r in candidates if limits.met(_bounded_figures(r))]
    if not candidates:
        raise InputError(f"--choose best: no setting that settles everywhere has "
                         f"{limits.text()} {LIMITS_WHERE}; widen the grid or the limits")  # fmt: skip

    def key(r: RobustRow) -> tuple[float, float, int]:
        assert r.score is not None
        settling = r.score.value("settling_time_s", "nominal")
        return (_rounded(r.score.value("overshoot_percent", "worst")),
                settling if math.isfinite(settling) else math.inf, r.index)  # fmt: skip

    return min(candidates, key=key)


def choose_best_nominal(results: Sequence[TuneResult], limits: Limits = Limits()) -> TuneResult:
    """``--choose best`` without ``--robust`` (:data:`CHOICE_RULE_NOMINAL`), within ``limits``;
    InputError when no setting qualifies."""
    candidates = [r for r in results if r.feasible and r.worst["settling_time_s"] is not None
                  and r.worst["overshoot_percent"] is not None]  # fmt: skip
    if not candidates:
        raise InputError("--choose best: no feasible setting settles; widen the grid or pick one "
                         "with --choose N")  # fmt: skip
    candidates = [r for r in candidates
                  if limits.met([(r.worst["overshoot_percent"], r.worst["settling_time_s"])])]  # fmt: skip
    if not candidates:
        raise InputError(f"--choose best: no setting that settles has {limits.text()} "
                         f"{LIMITS_WHERE_NOMINAL}; widen the grid or the limits")  # fmt: skip
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
