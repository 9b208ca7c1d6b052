"""``cartctl tune``'s text: the counts line, the legend and the tables (plain and ``--robust``).

Every column says what it is and its unit: ``design …`` columns are the grid setting asked of
``cartctl design``, ``run …`` columns what the simulated run measured (the worse of motors a
and b). Each column (or group of columns, with ``--robust``) has one rounding:
:data:`cartctl.measures.numfmt.SIG_FIGS` significant figures of its largest value
(:mod:`cartctl.measures.numfmt`). The settings are counted by status (:data:`cartctl.tune.grid.STATUSES`):
the infeasible requests, which the design refused and which never ran, apart from the runs that
did not settle.
"""

from __future__ import annotations

from collections.abc import Sequence

from cartctl.measures.numfmt import column_decimals, exact_decimals, format_column, format_fixed
from cartctl.tune.grid import AXES, STATUSES, TuneResult, status_counts
from cartctl.tune.robust import RobustRow

ROBUST_STATUSES = {
    "infeasible": STATUSES["infeasible"],
    "run failed": STATUSES["run failed"],
    "no step": STATUSES["no step"],
    "not settled": "ran, but did not settle on the model",
    "settled on some": "settled on the model, not on every sampled plant and physics run",
    "settled on all": "settled on the model, every sampled plant and every physics run",
}
"""A ``--robust`` row's status and what it means."""

LEGEND = (
    "design …: the grid setting asked of cartctl design; run …: measured in the simulated run, "
    "the worse of motors a and b"
)


def plural(n: int, one: str, many: str) -> str:
    """'1 setting', '2 settings'."""
    return f"{n} {one if n == 1 else many}"


def _counts_line(n_settings: int, c: dict[str, int], outcomes: Sequence[str]) -> str:
    """The settings counted: the infeasible requests, the runs that failed and those without a
    step to measure (if any), then ``outcomes`` (the counts of the runs that were measured)."""
    parts = [plural(c["infeasible"], "infeasible request (the design refused it)",
                    "infeasible requests (the design refused them)")]  # fmt: skip
    if c["run failed"]:
        parts.append(plural(c["run failed"], "run failed", "runs failed"))
    if c["no step"]:
        parts.append(f"{c['no step']} ran without a step in the reference to measure")
    return f"{plural(n_settings, 'setting', 'settings')}: " + ", ".join([*parts, *outcomes])


def counts_text(results: Sequence[TuneResult]) -> str:
    """'42 settings: 10 infeasible requests (the design refused them), 0 ran but did not settle,
    32 settled' (runs that failed and runs without a step to measure, if any, counted apart)."""
    c = status_counts(results)
    outcomes = [f"{c['not settled']} ran but did not settle", f"{c['settled']} settled"]
    return _counts_line(len(results), c, outcomes)


def robust_status(row: RobustRow) -> str:
    """One of :data:`ROBUST_STATUSES`."""
    status = row.result.status
    if status != "settled" or row.score is None:
        return status
    return "settled on all" if row.score.settles_everywhere else "settled on some"


def robust_counts(rows: Sequence[RobustRow]) -> dict[str, int]:
    """How many rows have each status of :data:`ROBUST_STATUSES` (all keys)."""
    counts = dict.fromkeys(ROBUST_STATUSES, 0)
    for r in rows:
        counts[robust_status(r)] += 1
    return counts


def robust_counts_text(rows: Sequence[RobustRow]) -> str:
    """The counts line of ``--robust``."""
    c = robust_counts(rows)
    outcomes = [
        f"{c['not settled']} ran but did not settle on the model",
        f"{c['settled on some']} settled on the model but not on every plant",
        f"{c['settled on all']} settled on every plant",
    ]
    return _counts_line(len(rows), c, outcomes)


def _settings_columns(method: str, results: Sequence[TuneResult]) -> tuple[list[str], list[list[str]]]:  # fmt: skip
    """Headers and cells of the design columns: each axis with the decimals its values need."""
    heads, cells = [], []
    for a in AXES[method]:
        values = [r.settings[a.name] for r in results]
        decimals = exact_decimals(values)
        heads.append(f"design {a.name} ({a.unit})")
        cells.append([format_fixed(v, decimals) for v in values])
    return heads, cells


def _render(headers: Sequence[str], columns: Sequence[Sequence[str]], left: Sequence[int],
            groups: Sequence[tuple[str, int, int]] = ()) -> list[str]:  # fmt: skip
    """Right-aligned columns (``left``: left-aligned), two spaces apart; ``groups`` (label, first
    column, last column) print centred on a line above their columns."""
    rows = list(zip(*columns, strict=True)) if columns and columns[0] else []
    widths = [max([len(h), *(len(r[i]) for r in rows)]) for i, h in enumerate(headers)]
    for label, first, last in groups:  # widen the last column of a group to fit its label
        span = sum(widths[first : last + 1]) + 2 * (last - first)
        widths[last] += max(0, len(label) - span)

    def line(cells: Sequence[str]) -> str:
        return "  ".join(c.ljust(w) if i in left else c.rjust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True))).rstrip()  # fmt: skip

    lines = []
    if groups:
        top, at = "", 0
        for label, first, last in groups:
            start = sum(widths[:first]) + 2 * first
            span = sum(widths[first : last + 1]) + 2 * (last - first)
            top += " " * (start - at) + label.center(span)
            at = start + span
        lines.append(top.rstrip())
    return [*lines, line(headers), *(line(r) for r in rows)]


def format_table(method: str, results: Sequence[TuneResult]) -> str:
    """The plain table: front marks, index, design columns, run columns (with units), status;
    the reasons of the settings that did not run below it.

    Front marks: ``*`` on the Pareto front over the four run metrics, ``o`` on the front of run
    settling against run overshoot (the axes of ``--plot``, which rings them).
    """
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
    columns = [marks, [str(r.index) for r in results], *cells, [r.status for r in results]]
    lines = _render(["front", "#", *heads, "status"], columns, left=(0, len(heads) + 2))
    lines += [f"  #{r.index}: {r.reason}" for r in results if not r.feasible]
    return "\n".join(lines)


def _group(values: Sequence[float | None], factor: float = 1.0) -> int:
    return column_decimals([None if v is None else v * factor for v in values])


def format_robust_table(method: str, rows: Sequence[RobustRow]) -> str:
    """The ``--robust`` table: ``*`` marks the robust Pareto front (nominal settling against
    worst-case overshoot, the axes of ``--plot``); the reasons of the settings that did not run
    below it. Each group (overshoot, settling) has one rounding over its columns."""
    heads, cells = _settings_columns(method, [r.result for r in rows])
    scored = [r.score for r in rows]

    def figure(metric: str, which: str) -> list[float | None]:
        return [None if s is None else s.figures[metric][which] for s in scored]

    def physics(metric: str) -> list[float | None]:
        return [None if s is None else s.physics.get(metric) for s in scored]

    spread = ("nominal", "worst", "p5", "p95")
    groups = []
    for metric, factor, label in (("overshoot_percent", 1.0, "run overshoot (%)"),
                                  ("settling_time_s", 1e3, "run settling (ms)")):  # fmt: skip
        d = _group([v for w in spread for v in figure(metric, w) if v != float("inf")], factor)

        def show(values: list[float | None], f: float = factor, d: int = d) -> list[str]:
            return [format_fixed(None if v is None else v * f, d) for v in values]

        first = len(heads) + 2
        heads += ["nominal", "worst", "p5–p95"]
        cells += [show(figure(metric, "nominal")), show(figure(metric, "worst")),
                  [f"{a}–{b}" for a, b in zip(show(figure(metric, "p5")),
                                              show(figure(metric, "p95")), strict=True)]]  # fmt: skip
        groups.append((label, first, first + 2))
    timings = next((s.actuation for s in scored if s is not None and s.actuation), ())
    if not timings:
        first = len(heads) + 2
        heads += ["overshoot (%)", "settling (ms)"]
        cells += [format_column(physics("overshoot_percent")),
                  format_column(physics("settling_time_s"), factor=1e3)]  # fmt: skip
        groups.append(("physics run", first, first + 1))
    for i, timing in enumerate(timings):  # the physics runs in the worst case, one group each

        def timed(metric: str, i: int = i) -> list[float | None]:
            return [None if s is None else s.actuation[i].get(metric) for s in scored]

        first = len(heads) + 2
        heads += ["overshoot (%)", "settling (ms)"]
        cells += [format_column(timed("overshoot_percent")),
                  format_column(timed("settling_time_s"), factor=1e3)]  # fmt: skip
        groups.append((f"physics run, {timing['actuation_ms']:g} ms", first, first + 1))
    heads.append("worst peak |V| (V)")
    cells.append(format_column(figure("peak_voltage_v", "worst")))
    marks = ["*" if r.pareto else "" for r in rows]
    statuses = [robust_status(r) for r in rows]
    columns = [marks, [str(r.index) for r in rows], *cells, statuses]
    blank = [i for i, s in enumerate(scored) if s is None]
    for col in columns[2 + len(AXES[method]) : -1]:  # the unscored rows: blank figures
        for i in blank:
            col[i] = ""
    lines = _render(["front", "#", *heads, "status"], columns, left=(0, len(heads) + 2),
                    groups=groups)  # fmt: skip
    lines += [f"  #{r.index}: {r.result.reason}" for r in rows if r.score is None]
    return "\n".join(lines)
