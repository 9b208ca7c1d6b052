"""The project's Rerun layout: entity paths, series styles and the blueprint (contract 4).

What a recording holds and how it is shown, shared by the run's sink (:mod:`cartctl.sinks.rerun_sink`)
and ``cartctl review``: per motor, speed with reference and estimate in one plot and the voltage
beneath, then the loop's timing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import rerun.blueprint as rrb

ENTITY_PATHS: Final[dict[str, str]] = {
    "reference_a": "motor/a/reference",
    "speed_a": "motor/a/speed",
    "estimate_a": "motor/a/estimate",
    "voltage_a": "motor/a/voltage",
    "reference_b": "motor/b/reference",
    "speed_b": "motor/b/speed",
    "estimate_b": "motor/b/estimate",
    "voltage_b": "motor/b/voltage",
    "period_error_us": "loop/period_error_us",
    "compute_us": "loop/compute_us",
    "true_speed_a": "motor/a/true_speed",
    "true_speed_b": "motor/b/true_speed",
}
"""Trace column → entity path. The first ten are contract 4; ``true_speed_*`` (simulated plants
only) is an extension."""

TIME_COLUMN: Final[str] = "time_s"
TICK_COLUMN: Final[str] = "tick"


@dataclass(frozen=True)
class SeriesStyle:
    """How one entity's line is drawn: legend label, colour (RGB, 0–255) and width (UI points)."""

    name: str
    color: tuple[int, int, int]
    width: float = 1.5


# The viewer draws a plot's series in entity-path order (estimate, reference, speed, true_speed),
# so the estimate is drawn wider to stay visible under a noisy measured speed.
_REFERENCE = SeriesStyle("reference (rad/s)", (150, 150, 150), 1.5)
_SPEED = SeriesStyle("measured speed (rad/s)", (31, 119, 180), 1.0)
_ESTIMATE = SeriesStyle("estimate (rad/s)", (255, 127, 14), 2.5)
_TRUE = SeriesStyle("true speed (rad/s)", (44, 160, 44), 1.0)
_VOLTAGE = SeriesStyle("voltage (V)", (148, 103, 189), 1.5)

STYLES: Final[dict[str, SeriesStyle]] = {
    "motor/a/reference": _REFERENCE,
    "motor/a/speed": _SPEED,
    "motor/a/estimate": _ESTIMATE,
    "motor/a/true_speed": _TRUE,
    "motor/a/voltage": _VOLTAGE,
    "motor/b/reference": _REFERENCE,
    "motor/b/speed": _SPEED,
    "motor/b/estimate": _ESTIMATE,
    "motor/b/true_speed": _TRUE,
    "motor/b/voltage": _VOLTAGE,
    "loop/period_error_us": SeriesStyle("period error (µs)", (214, 39, 40), 1.0),
    "loop/compute_us": SeriesStyle("compute time (µs)", (23, 190, 207), 1.0),
}


def blueprint(motors: Sequence[str] = ("a", "b")) -> rrb.Blueprint:
    """The project's default layout.

    The motors side by side; for each, speed with its reference and estimate (and the true speed of
    a simulated plant) above the voltage. The loop timing (period error and compute time) spans the
    bottom. Side panels start collapsed and the plots follow the ``time`` timeline.

    Parameters
    ----------
    motors : sequence of str
        Motor names, as in the entity paths ``motor/<name>/...``.

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    columns = []
    for m in motors:
        speed = rrb.TimeSeriesView(
            name=f"Motor {m.upper()}: speed (rad/s)",
            origin=f"/motor/{m}",
            contents=["$origin/**", "- $origin/voltage"],
            plot_legend=rrb.PlotLegend(corner="RightBottom", visible=True),
        )
        voltage = rrb.TimeSeriesView(
            name=f"Motor {m.upper()}: voltage (V)",
            origin=f"/motor/{m}/voltage",
            plot_legend=rrb.PlotLegend(visible=False),
        )
        columns.append(rrb.Vertical(speed, voltage, row_shares=[3, 2]))
    timing = rrb.TimeSeriesView(
        name="Loop timing (µs)",
        origin="/loop",
        plot_legend=rrb.PlotLegend(corner="RightTop", visible=True),
    )
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(*columns), timing, row_shares=[3, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="time"),
    )
