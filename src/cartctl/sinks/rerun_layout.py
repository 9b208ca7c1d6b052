"""The project's Rerun layout: entity paths, series styles and the blueprint.

The entity paths of the loop's columns are fixed (docs/architecture.md, "Rerun entity paths").

What a recording holds and how it is shown, shared by the run's sink (:mod:`cartctl.sinks.rerun_sink`)
and ``cartctl review``: per motor, speed with reference and estimate in one plot and the voltage
beneath, then the loop's timing.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Final

import rerun.blueprint as rrb

from cartctl.data.trace import MOTORS

TIME_COLUMN: Final[str] = "time_s"
TICK_COLUMN: Final[str] = "tick"


@dataclass(frozen=True)
class SeriesStyle:
    """How one entity's line is drawn: legend label, colour (RGB, 0–255) and width (UI points)."""

    name: str
    color: tuple[int, int, int]
    width: float = 1.5


# The viewer draws a plot's series in entity-path order (estimate, reference, smoothed_speed,
# speed, true_speed), so the estimate is drawn wider to stay visible under a noisy measured speed.
_MOTOR_SERIES: Final[dict[str, SeriesStyle]] = {
    "reference": SeriesStyle("reference (rad/s)", (150, 150, 150), 1.5),
    "speed": SeriesStyle("measured speed (rad/s)", (31, 119, 180), 1.0),
    "estimate": SeriesStyle("estimate (rad/s)", (255, 127, 14), 2.5),
    "true_speed": SeriesStyle("true speed (rad/s)", (44, 160, 44), 1.0),
    "smoothed_speed": SeriesStyle("smoothed speed (rad/s)", (227, 119, 194), 1.5),
    "voltage": SeriesStyle("voltage (V)", (148, 103, 189), 1.5),
}
"""Per motor: trace column ``<kind>_<m>`` → entity ``motor/<m>/<kind>``, drawn in this style."""
_LOOP_SERIES: Final[dict[str, SeriesStyle]] = {
    "period_error_us": SeriesStyle("period error (µs)", (214, 39, 40), 1.0),
    "compute_us": SeriesStyle("compute time (µs)", (23, 190, 207), 1.0),
}
"""The loop's timing: trace column ``<name>`` → entity ``loop/<name>``."""

_TABLE: Final[dict[str, tuple[str, SeriesStyle]]] = {
    **{f"{kind}_{m}": (f"motor/{m}/{kind}", style)
       for m in MOTORS for kind, style in _MOTOR_SERIES.items()},
    **{name: (f"loop/{name}", style) for name, style in _LOOP_SERIES.items()},
}  # fmt: skip

ENTITY_PATHS: Final[dict[str, str]] = {column: path for column, (path, _) in _TABLE.items()}
"""Trace column → entity path. Those of the columns the loop writes are fixed
(docs/architecture.md); ``true_speed_*`` (simulated plants only) and ``smoothed_speed_*`` (the
Kalman RTS smoothed speed, computed after a run from the whole trace,
:mod:`cartctl.design.smoother`; not a column the loop writes) are extensions."""
STYLES: Final[dict[str, SeriesStyle]] = {path: style for path, style in _TABLE.values()}
"""Entity path → how its line is drawn."""


Range = tuple[float, float]
"""A plot's y range (lo, hi), in the plot's unit."""


@dataclass(frozen=True)
class PlotRanges:
    """The y range of each plot of the layout (None: the viewer's own fit).

    A viewer fitting its axes to a run that has only just started (or to signals that are all 0)
    shows a range of ±1 labelled "0" alone; explicit ranges make the axes readable from the first
    tick. :func:`run_ranges` makes them from what a run knows beforehand, the review from the
    recorded data.
    """

    speed_rad_s: dict[str, Range] = field(default_factory=dict)
    """Per motor: the speed plot (reference, speed, estimate)."""
    voltage_v: dict[str, Range] = field(default_factory=dict)
    """Per motor: the voltage plot."""
    timing_us: Range | None = None
    """The loop timing plot (period error and compute time)."""


SPEED_MARGIN = 0.25
"""Room above and below the reference's span in the speed plot (overshoot), as a fraction of it."""
VOLTAGE_MARGIN = 0.05
"""Room beyond the voltage limit in the voltage plot, as a fraction of it."""


def motors_in(entities: Iterable[str]) -> tuple[str, ...]:
    """Motor names among entity paths (``motor/a/speed`` → ``a``), in order; both when none is."""
    names: list[str] = []
    for entity in entities:
        parts = entity.split("/")
        if parts[0] == "motor" and len(parts) > 1 and parts[1] not in names:
            names.append(parts[1])
    return tuple(names) or ("a", "b")


def padded_range(lo: float, hi: float, *, margin: float = 0.1, min_span: float = 1.0) -> Range:
    """A y range holding 0, ``lo`` and ``hi``, widened by ``margin`` of its span on each side.

    The span is at least ``min_span`` (signals that stay at 0 get (−0.1, 1.1) by default, not a
    range that collapses).
    """
    lo, hi = min(float(lo), 0.0), max(float(hi), 0.0)
    if hi - lo < min_span:
        hi = lo + min_span if hi > 0.0 or lo == 0.0 else hi
        lo = hi - min_span
    pad = margin * (hi - lo)
    return lo - pad, hi + pad


def run_ranges(references: dict[str, tuple[float, float]], voltage_limit_v: float) -> PlotRanges:
    """The plots' ranges before a run: speed from each motor's reference, voltage from the limit.

    Parameters
    ----------
    references : dict of str to (float, float)
        Per motor, the reference's lowest and highest value over the run (rad/s).
    voltage_limit_v : float
        The controllers' voltage limit (V): the voltage plot spans ± it.
    """
    limit = abs(float(voltage_limit_v)) * (1.0 + VOLTAGE_MARGIN)
    return PlotRanges(
        speed_rad_s={
            m: padded_range(lo, hi, margin=SPEED_MARGIN) for m, (lo, hi) in references.items()
        },
        voltage_v={m: (-limit, limit) for m in references},
    )


def _axis(ranged: Range | None) -> rrb.ScalarAxis | None:
    return None if ranged is None else rrb.ScalarAxis(range=ranged, zoom_lock=False)


def blueprint(
    motors: Sequence[str] = ("a", "b"), ranges: PlotRanges | None = None
) -> rrb.Blueprint:
    """The project's default layout.

    The motors side by side; for each, speed with its reference and estimate (and the true speed of
    a simulated plant, the smoothed speed where a run or review made one) above the voltage. The loop timing (period error and compute time) spans the
    bottom. Side panels start collapsed and the plots follow the ``time`` timeline.

    Parameters
    ----------
    motors : sequence of str
        Motor names, as in the entity paths ``motor/<name>/...``.
    ranges : PlotRanges, optional
        The plots' y ranges; without, the viewer fits them.

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    ranges = ranges or PlotRanges()
    columns = []
    for m in motors:
        speed = rrb.TimeSeriesView(
            name=f"Motor {m.upper()}: speed (rad/s)",
            origin=f"/motor/{m}",
            contents=["$origin/**", "- $origin/voltage"],
            plot_legend=rrb.PlotLegend(corner="RightBottom", visible=True),
            axis_y=_axis(ranges.speed_rad_s.get(m)),
        )
        voltage = rrb.TimeSeriesView(
            name=f"Motor {m.upper()}: voltage (V)",
            origin=f"/motor/{m}/voltage",
            plot_legend=rrb.PlotLegend(visible=False),
            axis_y=_axis(ranges.voltage_v.get(m)),
        )
        columns.append(rrb.Vertical(speed, voltage, row_shares=[3, 2]))
    timing = rrb.TimeSeriesView(
        name="Loop timing (µs)",
        origin="/loop",
        plot_legend=rrb.PlotLegend(corner="RightTop", visible=True),
        axis_y=_axis(ranges.timing_us),
    )
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(*columns), timing, row_shares=[3, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="time"),
    )


def data_ranges(extremes: dict[str, Range], motors: Sequence[str]) -> PlotRanges:
    """The plots' ranges from the recorded values: ``extremes`` is entity path → (min, max).

    Each plot spans its series' values (and 0) with 10 % to spare.
    """

    def over(paths: Sequence[str], **kwargs: float) -> Range | None:
        seen = [extremes[p] for p in paths if p in extremes]
        if not seen:
            return None
        return padded_range(min(lo for lo, _ in seen), max(hi for _, hi in seen), **kwargs)

    speeds = ("reference", "speed", "estimate", "true_speed", "smoothed_speed")
    return PlotRanges(
        speed_rad_s={
            m: r for m in motors if (r := over([f"motor/{m}/{s}" for s in speeds])) is not None
        },
        voltage_v={m: r for m in motors if (r := over([f"motor/{m}/voltage"])) is not None},
        timing_us=over(["loop/period_error_us", "loop/compute_us"], min_span=10.0),
    )
