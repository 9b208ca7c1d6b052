"""``cartctl tune`` after the scoring: the fronts' order, the ``--choose best`` rules
(:data:`CHOICE_RULE`, :data:`CHOICE_RULE_NOMINAL`) and the text (counts, legend, tables: ``design
…`` columns the setting asked of ``cartctl design``, ``run …`` columns what the simulated run
measured, the worse of motors a and b, one rounding per column or ``--robust`` group). The robust
Pareto front is nominal settling against worst-case overshoot, among settings where both are
finite."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np

from cartctl.errors import InputError
from cartctl.measures.numfmt import (
    column_decimals,
    exact_decimals,
    format_column,
    format_fixed,
    render_table,
)
from cartctl.tune.grid import AXES, STATUSES, TuneResult, pareto_front, status_counts
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
    nan = (math.nan, math.nan)
    points = np.array([nan if r.score is None else r.score.front_axes for r in rows]).reshape(-1, 2)
    front = pareto_front(np.where(np.isfinite(points), points, np.nan))
    return [replace(r, pareto=bool(f)) for r, f in zip(rows, front, strict=True)]


@dataclass(frozen=True)
class Limits:
    """``--max-overshoot`` (%) and ``--max-settling`` (s), None: no bound. ``--choose best`` applies
    them to the nominal run and (with ``--robust``) the physics runs at every actuation timing, not
    to the sampled plants (whose worst case ranks the settings)."""

    overshoot_percent: float | None = None
    settling_time_s: float | None = None

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
        bounds = (self.overshoot_percent, self.settling_time_s)
        return all(
            bound is None or (value is not None and value <= bound)
            for figure in figures
            for value, bound in zip(figure, bounds, strict=True)
        )


def rule_text(rule: str, limits: Limits, where: str) -> str:
    """``rule`` with the bounds of ``limits`` (where they apply) in front of it."""
    if not limits.text():  # no bounds
        return rule
    return f"among the settings with {limits.text()} {where}: {rule}"


LIMITS_WHERE = "on the model and on the physics preset at each --actuation-ms"
LIMITS_WHERE_NOMINAL = "on the plant (worse of motors a and b)"


def _bounded_figures(r: RobustRow) -> list[tuple[float | None, float | None]]:
    assert r.score is not None
    nominal = r.score.figures
    figures = [(nominal["overshoot_percent"]["nominal"], nominal["settling_time_s"]["nominal"])]
    figures += [(e.get("overshoot_percent"), e.get("settling_time_s")) for e in r.score.actuation]
    return figures


Choosable = TypeVar("Choosable", RobustRow, TuneResult)


def _best(
    candidates: Sequence[Choosable],
    limits: Limits,
    figures: Callable[[Choosable], list[tuple[float | None, float | None]]],
    rank: Callable[[Choosable], tuple[Any, Any]],
    words: tuple[str, str, str],
) -> Choosable:
    """The best of ``candidates`` by ``rank``'s overshoot (to :data:`CHOICE_RESOLUTION_PERCENT`),
    settling and index, of those whose ``figures`` meet ``limits``; ``words`` word the refusals."""
    if not candidates:
        raise InputError(
            f"--choose best: no feasible setting {words[0]}; widen the grid or pick one with "
            "--choose N"
        )
    within = [r for r in candidates if limits.met(figures(r))]
    if not within:
        raise InputError(
            f"--choose best: no setting that {words[1]} has {limits.text()} {words[2]}; widen the "
            "grid or the limits"
        )

    def key(r: Choosable) -> tuple[float, float, int]:
        overshoot, settling = rank(r)
        return round(overshoot / CHOICE_RESOLUTION_PERCENT), settling, r.index

    return min(within, key=key)


def choose_best_robust(rows: Sequence[RobustRow], limits: Limits = Limits()) -> RobustRow:
    """``--choose best`` with ``--robust`` (:data:`CHOICE_RULE`), within ``limits``; InputError when
    no setting qualifies."""

    def rank(r: RobustRow) -> tuple[float, float]:
        assert r.score is not None
        settling, worst = r.score.front_axes
        return worst, settling if math.isfinite(settling) else math.inf

    candidates = [
        r
        for r in rows
        if r.score is not None
        and r.score.settles_everywhere
        and math.isfinite(r.score.value("overshoot_percent", "worst"))
    ]
    words = ("settles on every sampled plant and physics run", "settles everywhere", LIMITS_WHERE)
    return _best(candidates, limits, _bounded_figures, rank, words)


def choose_best_nominal(results: Sequence[TuneResult], limits: Limits = Limits()) -> TuneResult:
    """``--choose best`` without ``--robust`` (:data:`CHOICE_RULE_NOMINAL`), within ``limits``;
    InputError when no setting qualifies."""

    def figures(r: TuneResult) -> list[tuple[float | None, float | None]]:
        return [(r.worst["overshoot_percent"], r.worst["settling_time_s"])]

    candidates = [r for r in results if None not in figures(r)[0]]  # (all None if infeasible)
    words = ("settles", "settles", LIMITS_WHERE_NOMINAL)
    return _best(candidates, limits, figures, lambda r: figures(r)[0], words)


def sort_robust(rows: Sequence[RobustRow]) -> list[RobustRow]:
    """Robust front first (by nominal settling), then the other scored settings by worst-case
    overshoot, then the infeasible (by index)."""

    def key(r: RobustRow) -> tuple[int, float, float, int]:
        if r.score is None:
            return (3, 0.0, 0.0, r.index)
        settling, worst = (math.inf if math.isnan(v) else v for v in r.score.front_axes)
        if r.pareto:
            return (0, settling, worst, r.index)
        return (1, worst, settling, r.index)

    return sorted(rows, key=key)


ROBUST_STATUSES = {
    **{s: STATUSES[s] for s in ("infeasible", "run failed", "no step")},
    "not settled": "ran, but did not settle on the model",
    "settled on some": "settled on the model, not on every sampled plant and physics run",
    "settled on all": "settled on the model, every sampled plant and every physics run",
}

LEGEND = (
    "design …: the grid setting asked of cartctl design; run …: measured in the simulated run, "
    "the worse of motors a and b"
)


def plural(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def _counts_line(n_settings: int, c: dict[str, int], outcomes: Sequence[str]) -> str:
    """The settings counted: infeasible, failed and stepless runs (if any), then ``outcomes``."""
    parts = [plural(c["infeasible"], "infeasible request (the design refused it)",
                    "infeasible requests (the design refused them)")]  # fmt: skip
    if c["run failed"]:
        parts.append(plural(c["run failed"], "run failed", "runs failed"))
    if c["no step"]:
        parts.append(f"{c['no step']} ran without a step in the reference to measure")
    return f"{plural(n_settings, 'setting', 'settings')}: " + ", ".join([*parts, *outcomes])


def counts_text(results: Sequence[TuneResult]) -> str:
    """'42 settings: 10 infeasible requests (the design refused them), 0 ran but did not settle,
    32 settled'."""
    c = status_counts(results)
    outcomes = [f"{c['not settled']} ran but did not settle", f"{c['settled']} settled"]
    return _counts_line(len(results), c, outcomes)


def robust_status(row: RobustRow) -> str:
    status = row.result.status
    if status != "settled" or row.score is None:
        return status
    return "settled on all" if row.score.settles_everywhere else "settled on some"


def robust_counts(rows: Sequence[RobustRow]) -> dict[str, int]:
    return {s: sum(robust_status(r) == s for r in rows) for s in ROBUST_STATUSES}


def robust_counts_text(rows: Sequence[RobustRow]) -> str:
    c = robust_counts(rows)
    outcomes = [
        f"{c['not settled']} ran but did not settle on the model",
        f"{c['settled on some']} settled on the model but not on every plant",
        f"{c['settled on all']} settled on every plant",
    ]
    return _counts_line(len(rows), c, outcomes)


def _settings_columns(method: str, results: Sequence[TuneResult]) -> tuple[list[str], list[list[str]]]:  # fmt: skip
    """Headers and cells of the design columns, each axis with the decimals its values need."""
    heads, cells = [], []
    for a in AXES[method]:
        values = [r.settings[a.name] for r in results]
        decimals = exact_decimals(values)
        heads.append(f"design {a.name} ({a.unit})")
        cells.append([format_fixed(v, decimals) for v in values])
    return heads, cells


def format_table(method: str, results: Sequence[TuneResult]) -> str:
    """The plain table, with the reasons of the settings that did not run below it. Front marks:
    ``*`` on the Pareto front over the four run metrics, ``o`` on the front of run settling against
    run overshoot (the axes of ``--plot``)."""
    heads, cells = _settings_columns(method, results)
    worst = [r.worst for r in results]
    run = [("run overshoot (%)", "overshoot_percent", 1.0),
           ("run settling (ms)", "settling_time_s", 1e3),
           ("run rms error (rad/s)", "rms_error", 1.0),
           ("run peak |V| (V)", "max_abs_voltage", 1.0)]  # fmt: skip
    for head, key, factor in run:
        heads.append(head)
        cells.append(format_column([w[key] for w in worst], factor=factor))
    marks = [("*" if r.pareto else "") + ("o" if r.pareto_plot else "") for r in results]
    return _lines(marks, results, heads, cells, [r.status for r in results])


def _lines(marks: list[str], results: Sequence[TuneResult], heads: list[str],
           cells: list[list[str]], statuses: list[str],
           groups: Sequence[tuple[str, int, int]] = ()) -> str:  # fmt: skip
    """The table under its headers, then the reasons of the settings that did not run."""
    columns = [marks, [str(r.index) for r in results], *cells, statuses]
    lines = render_table(["front", "#", *heads, "status"], list(zip(*columns, strict=True)),
                         left=(0, len(heads) + 2), groups=groups)  # fmt: skip
    lines += [f"  #{r.index}: {r.reason}" for r in results if not r.feasible]
    return "\n".join(lines)


SPREAD = ("nominal", "worst", "p5", "p95")  # the figures of a --robust table's group


def format_robust_table(method: str, rows: Sequence[RobustRow]) -> str:
    """The ``--robust`` table: ``*`` marks the robust front; one rounding per group (overshoot,
    settling); the reasons of the settings that did not run below it."""
    heads, cells = _settings_columns(method, [r.result for r in rows])
    scored = [r.score for r in rows]
    groups: list[tuple[str, int, int]] = []

    def group(label: str, columns: dict[str, list[str]]) -> None:
        groups.append((label, len(heads) + 2, len(heads) + 1 + len(columns)))
        heads.extend(columns)
        cells.extend(columns.values())

    for metric, factor, label in (("overshoot_percent", 1.0, "run overshoot (%)"),
                                  ("settling_time_s", 1e3, "run settling (ms)")):  # fmt: skip
        figures = [[None if s is None else s.figures[metric][w] for s in scored] for w in SPREAD]
        scaled = [[None if v is None else v * factor for v in values] for values in figures]
        d = column_decimals(v for values in scaled for v in values)
        text = {w: [format_fixed(v, d) for v in vs] for w, vs in zip(SPREAD, scaled, strict=True)}
        spread = [f"{a}–{b}" for a, b in zip(text["p5"], text["p95"], strict=True)]
        group(label, {"nominal": text["nominal"], "worst": text["worst"], "p5–p95": spread})
    timings = next((s.actuation for s in scored if s is not None and s.actuation), ())
    # the physics preset, or the physics runs in the worst case: one group each
    runs = (
        [("physics run", [{} if s is None else s.physics for s in scored])] if not timings else []
    )
    runs += [(f"physics run, {t['actuation_ms']:g} ms",
              [{} if s is None else s.actuation[i] for s in scored])
             for i, t in enumerate(timings)]  # fmt: skip
    for label, entries in runs:
        overshoot = format_column([e.get("overshoot_percent") for e in entries])
        settling = format_column([e.get("settling_time_s") for e in entries], factor=1e3)
        group(label, {"overshoot (%)": overshoot, "settling (ms)": settling})
    heads.append("worst peak |V| (V)")
    peak = [None if s is None else s.figures["peak_voltage_v"]["worst"] for s in scored]
    cells.append(format_column(peak))
    for col in cells[len(AXES[method]) :]:  # the unscored rows: blank figures
        for i, s in enumerate(scored):
            col[i] = col[i] if s is not None else ""
    marks, statuses = ["*" if r.pareto else "" for r in rows], [robust_status(r) for r in rows]
    return _lines(marks, [r.result for r in rows], heads, cells, statuses, groups)
