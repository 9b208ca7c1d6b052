"""Grid tuning, the pure part: the ``--grid`` spec, a setting's design request, result rows, fronts.

``--grid`` holds comma-separated axes, each ``NAME=START:STOP:STEP`` (inclusive, STEP > 0) or
``NAME=VALUE``; axes left out keep their default range (:data:`AXES`). NAME is the ``cartctl
design`` option without its dashes; the older spelling with underscores is accepted too."""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.choices import MAX_TUNE_SETTINGS
from cartctl.design.request import DesignRequest, check_field
from cartctl.errors import InputError

METRICS = ("overshoot_percent", "settling_time_s", "rms_error", "max_abs_voltage")  # %, s, rad/s, V
PLOT_METRICS = ("settling_time_s", "overshoot_percent")  # --plot's x and y

STATUSES = {
    "infeasible": "infeasible request (the design refused it)",
    "run failed": "designed, but its run failed",
    "no step": "ran, but its reference has no step to measure (overshoot, settling undefined)",
    "not settled": "ran, but did not settle",
    "settled": "ran and settled",
}  # a setting's status (the worse of motors a and b)
RUN_FAILED = "the run failed: "  # how the reason of a setting whose run failed begins


@dataclass(frozen=True)
class Axis:
    """A tuning axis: its grid ``name`` (the design option without dashes; the settings' key in
    ``--json``), the design request ``field`` it sets, its ``unit`` and default range."""

    name: str
    field: str
    unit: str
    default: tuple[float, float, float]


AXES: dict[str, tuple[Axis, ...]] = {
    "pi": (
        Axis("phase-margin", "phase_margin_deg", "deg", (50.0, 75.0, 5.0)),
        Axis("crossover-hz", "crossover_hz", "Hz", (2.0, 5.0, 0.5)),
    ),
    "poles": (
        Axis("settling-time", "settling_time_s", "s", (0.04, 0.16, 0.02)),
        Axis("overshoot", "overshoot_percent", "%", (0.5, 5.0, 1.5)),
    ),
}

FIELDS = {a.name: a.field for axes in AXES.values() for a in axes}


def _count(start: float, stop: float, step: float) -> int:
    span = (stop - start) / step + 1e-9
    if not math.isfinite(span):  # a step too small for its span (1e-320)
        raise InputError(f"--grid: a step of {step:g} over {start:g}..{stop:g} gives more than "
                         f"{MAX_TUNE_SETTINGS} settings; use coarser steps")  # fmt: skip
    return math.floor(span) + 1


def _axis_range(item: str, text: str, form: str) -> tuple[float, float, float]:
    parts = [p.strip() for p in text.split(":")]
    if len(parts) not in (1, 3) or not all(parts):
        raise InputError(f"--grid {item}: expected START:STOP:STEP or one VALUE after the '='")
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        raise InputError(f"--grid {item}: the values must be numbers; expected {form}") from None
    if not all(math.isfinite(v) for v in numbers):
        raise InputError(f"--grid {item}: the values must be finite numbers (not nan or inf)")
    if len(numbers) == 1:
        return numbers[0], numbers[0], 1.0
    start, stop, step = numbers
    if step <= 0.0:
        raise InputError(f"--grid {item}: STEP must be > 0, got {step:g}")
    if start > stop:
        raise InputError(f"--grid {item}: START {start:g} is above STOP {stop:g}; the range is "
                         "empty")  # fmt: skip
    return start, stop, step


def parse_grid(spec: str | None, method: str) -> dict[str, tuple[float, ...]]:
    """The values of each axis of ``method`` by axis name, defaults where ``spec`` is silent; each
    checked as ``cartctl design`` checks its option, before any design runs, and unknown or repeated
    axes, malformed or empty ranges and more than :data:`MAX_TUNE_SETTINGS` settings refused."""
    spelled = {n: a.name for a in AXES[method] for n in (a.name, a.name.replace("-", "_"))}
    ranges = {a.name: a.default for a in AXES[method]}
    given: dict[str, str] = {}
    form = ",".join(f"{a.name}=START:STOP:STEP" for a in AXES[method])
    form = f"'{form}' (inclusive; or NAME=VALUE)"
    for item in (spec or "").split(",") if spec and spec.strip() else []:
        typed, eq, text = (s.strip() for s in item.partition("="))
        item = item.strip()
        if not eq or typed not in spelled:
            raise InputError(f"--grid: bad axis '{item}' for --method {method}; expected {form}")
        name = spelled[typed]
        if name in given:
            raise InputError(f"--grid: axis '{name}' is given twice ({given[name]}, {item})")
        given[name] = item
        ranges[name] = _axis_range(item, text, form)
    size = math.prod(_count(*r) for r in ranges.values())
    if size > MAX_TUNE_SETTINGS:
        raise InputError(
            f"--grid gives {size if size < 10**9 else 'over 10^9'} settings, more than "
            f"{MAX_TUNE_SETTINGS}; use coarser steps"
        )
    # start, start + step, … up to stop inclusive (to 1e-9 of a step), rounded to 1e-10
    values = {name: tuple(round(start + i * step, 10) for i in range(_count(start, stop, step)))
              for name, (start, stop, step) in ranges.items()}  # fmt: skip
    for name, axis_values in values.items():
        option = f"--grid {given[name]}" if name in given else f"the default --grid {name}"
        for v in axis_values:
            check_field(FIELDS[name], v, option)
    return values


def grid_settings(axes: Mapping[str, Sequence[float]]) -> list[dict[str, float]]:
    """Every combination of the axis values, the first axis varying slowest."""
    combinations = itertools.product(*axes.values())
    return [{n: float(v) for n, v in zip(axes, c, strict=True)} for c in combinations]


def design_request(
    method: str,
    settings: Mapping[str, float],
    extra_delay_ticks: int = 0,
    fixed: Mapping[str, Any] | None = None,
) -> DesignRequest:
    """A setting's design request: the design defaults, ``fixed`` (shared fields such as
    ``process_noise_std_v``), then the setting's axes (the tuning run's and ``--choose``'s)."""
    axes: dict[str, Any] = {a.field: float(settings[a.name]) for a in AXES[method]}
    return DesignRequest(method=method, extra_delay_ticks=extra_delay_ticks, **dict(fixed or {}),
                         **axes)  # fmt: skip


def request_axes(method: str) -> tuple[str, ...]:
    """The request fields of a method's axes (always written in the design command)."""
    return tuple(a.field for a in AXES[method])


def worst_metrics(motors: Mapping[str, Mapping[str, Any]]) -> dict[str, float | None]:
    """Per metric of :data:`METRICS`, the larger (worse) of the motors; None if any is None."""
    known = {key: [m[key] for m in motors.values() if m.get(key) is not None] for key in METRICS}
    return {k: float(max(v)) if v and len(v) == len(motors) else None for k, v in known.items()}


@dataclass(frozen=True)
class TuneResult:
    """One grid setting: what was asked, whether it was designed and ran, and how it ran. ``index``
    is the 1-based place in the grid (first axis slowest), which ``--choose`` takes; ``settings``
    the axis values by axis name; ``reason`` why it is infeasible (refused design or failed run);
    ``motors`` each motor's run summary entry (as ``run --json``); ``pareto`` and ``pareto_plot``
    mark the fronts over :data:`METRICS` and :data:`PLOT_METRICS`."""

    index: int
    settings: dict[str, float]
    feasible: bool
    reason: str | None = None
    motors: dict[str, dict[str, Any]] = field(default_factory=dict)
    pareto: bool = False
    pareto_plot: bool = False

    @property
    def status(self) -> str:
        """One of :data:`STATUSES`."""
        if not self.feasible:
            return "run failed" if (self.reason or "").startswith(RUN_FAILED) else "infeasible"
        worst = self.worst
        if worst["settling_time_s"] is not None:
            return "settled"
        return "no step" if worst["overshoot_percent"] is None else "not settled"

    @property
    def worst(self) -> dict[str, float | None]:
        """The worse of the motors per metric; all None when infeasible (no motors)."""
        return worst_metrics(self.motors)

    def to_dict(self) -> dict[str, Any]:
        """JSON row (``peak_voltage_v`` is the worse ``max_abs_voltage``)."""
        w = self.worst
        return {"index": self.index, "settings": dict(self.settings), "feasible": self.feasible,
                "reason": self.reason, **{k: w[k] for k in METRICS[:3]},
                "peak_voltage_v": w["max_abs_voltage"], "pareto": self.pareto, "motors": self.motors,
                "status": self.status, "pareto_plot": self.pareto_plot}  # fmt: skip


def pareto_front(points: ArrayLike) -> NDArray[np.bool_]:
    """Which rows of ``points`` (n, k) are non-dominated, every column minimised; a row with a NaN is
    never on the front and dominates nothing, equal rows do not dominate each other."""
    p = np.asarray(points, dtype=float)
    valid = ~np.isnan(p).any(axis=1)
    front = valid.copy()
    q = p[valid]
    for i in np.flatnonzero(valid):
        dominated = np.all(q <= p[i], axis=1) & np.any(q < p[i], axis=1)
        front[i] = not dominated.any()
    return front


def _front_over(results: Sequence[TuneResult], metrics: Sequence[str]) -> NDArray[np.bool_]:
    rows = np.array([[r.worst[k] for k in metrics] for r in results], dtype=float)  # None: NaN
    return pareto_front(rows.reshape(len(results), len(metrics)))


def mark_pareto(results: Sequence[TuneResult]) -> list[TuneResult]:
    """The results with ``pareto`` (the front over :data:`METRICS`) and ``pareto_plot`` (over
    :data:`PLOT_METRICS`) set, among feasible settings whose metrics are all defined."""
    front = _front_over(results, METRICS)
    plotted = _front_over(results, PLOT_METRICS)
    return [replace(r, pareto=bool(f), pareto_plot=bool(p))
            for r, f, p in zip(results, front, plotted, strict=True)]  # fmt: skip


def status_counts(results: Sequence[TuneResult]) -> dict[str, int]:
    """How many settings have each status of :data:`STATUSES` (all keys)."""
    return {s: sum(r.status == s for r in results) for s in STATUSES}


def sort_results(results: Sequence[TuneResult]) -> list[TuneResult]:
    """Pareto front first, then the other settled runs, each by settling then overshoot; then the
    unsettled (by RMS error), then the infeasible (by index)."""

    def key(r: TuneResult) -> tuple[int, float, float, int]:
        w = {k: math.inf if v is None else v for k, v in r.worst.items()}  # (no settling: inf)
        if not r.feasible:
            return (3, 0.0, 0.0, r.index)
        if w["settling_time_s"] == math.inf:
            return (2, w["rms_error"], 0.0, r.index)
        return (0 if r.pareto else 1, w["settling_time_s"], w["overshoot_percent"], r.index)

    return sorted(results, key=key)
