"""The project's Rerun layout: entity paths (docs/architecture.md), series styles, blueprints.

Shared by the run's sink and ``cartctl review``: per motor, speed with reference and estimate
above the voltage; the loop's timing beneath. ``cartctl monitor``'s channels are series under
``gpio/<label>``, the cart's messages under ``cart/``; review lays them out from their labels.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Literal

import rerun.blueprint as rrb

from cartctl.data.columns import label_key
from cartctl.data.trace import MOTORS

TIME_COLUMN: Final[str] = "time_s"
TICK_COLUMN: Final[str] = "tick"


@dataclass(frozen=True)
class SeriesStyle:
    """How one entity's line is drawn: legend label, colour (RGB, 0–255) and width (UI points)."""

    name: str
    color: tuple[int, int, int]
    width: float = 1.5


# Column <kind>_<m> → entity motor/<m>/<kind>; <name> → loop/<name>. Series are drawn in path
# order, so the estimate is wider to stay visible under a noisy measured speed.
_MOTOR_SERIES: Final[dict[str, SeriesStyle]] = {
    "reference": SeriesStyle("reference (rad/s)", (150, 150, 150), 1.5),
    "speed": SeriesStyle("measured speed (rad/s)", (31, 119, 180), 1.0),
    "estimate": SeriesStyle("estimate (rad/s)", (255, 127, 14), 2.5),
    "true_speed": SeriesStyle("true speed (rad/s)", (44, 160, 44), 1.0),
    "smoothed_speed": SeriesStyle("smoothed speed (rad/s)", (227, 119, 194), 1.5),
    "voltage": SeriesStyle("voltage (V)", (148, 103, 189), 1.5),
}
_LOOP_SERIES: Final[dict[str, SeriesStyle]] = {
    "period_error_us": SeriesStyle("period error (µs)", (214, 39, 40), 1.0),
    "compute_us": SeriesStyle("compute time (µs)", (23, 190, 207), 1.0),
}

_TABLE: Final[dict[str, tuple[str, SeriesStyle]]] = {
    **{f"{kind}_{m}": (f"motor/{m}/{kind}", style)
       for m in MOTORS for kind, style in _MOTOR_SERIES.items()},
    **{name: (f"loop/{name}", style) for name, style in _LOOP_SERIES.items()},
}  # fmt: skip

ENTITY_PATHS: Final[dict[str, str]] = {column: path for column, (path, _) in _TABLE.items()}
"""Trace column → entity path (docs/architecture.md; ``true_speed_*`` and ``smoothed_speed_*``
are extensions)."""
STYLES: Final[dict[str, SeriesStyle]] = {path: style for path, style in _TABLE.values()}


Range = tuple[float, float]
Ranges = Mapping[str, Range | None]
"""The y range of each plot by its origin (``motor/a``, ``motor/a/voltage``, ``loop``); a plot
without one takes the viewer's own fit, which shows ±1 labelled "0" alone until the run has data."""

SPEED_MARGIN = 0.25  # room for overshoot, a fraction of the reference's span
VOLTAGE_MARGIN = 0.05  # beyond the voltage limit


def motors_in(entities: Iterable[str]) -> tuple[str, ...]:
    """Motor names among entity paths (``motor/a/speed`` → ``a``), in order."""
    paths = (entity.split("/") for entity in entities)
    return tuple(dict.fromkeys(p[1] for p in paths if p[0] == "motor" and len(p) > 2))


def padded_range(lo: float, hi: float, *, margin: float = 0.1, min_span: float = 1.0) -> Range:
    """A y range holding 0, ``lo`` and ``hi``, at least ``min_span`` wide, widened by
    ``margin`` of its span on each side."""
    lo, hi = min(float(lo), 0.0), max(float(hi), 0.0)
    if hi - lo < min_span:
        hi = lo + min_span if hi > 0.0 or lo == 0.0 else hi
        lo = hi - min_span
    pad = margin * (hi - lo)
    return lo - pad, hi + pad


def run_ranges(references: dict[str, Range], voltage_limit_v: float) -> dict[str, Range]:
    """The plots' ranges before a run: speed from each motor's (lowest, highest) reference
    (rad/s), voltage ± the limit (V)."""
    limit = abs(float(voltage_limit_v)) * (1.0 + VOLTAGE_MARGIN)
    speeds = {
        f"motor/{m}": padded_range(*span, margin=SPEED_MARGIN) for m, span in references.items()
    }
    return speeds | {f"motor/{m}/voltage": (-limit, limit) for m in references}


def plot(
    name: str,
    origin: str,
    ranged: Range | None,
    contents: Sequence[str] | str = "$origin/**",
    legend: Literal["RightBottom", "RightTop"] | None = "RightBottom",
) -> rrb.TimeSeriesView:
    """A time-series view of the entity ``origin``, its y range ``ranged`` (None: the viewer's
    own fit), its legend in the corner ``legend`` (None: hidden)."""
    return rrb.TimeSeriesView(
        name=name,
        origin=f"/{origin}",
        contents=contents,
        plot_legend=rrb.PlotLegend(corner=legend, visible=legend is not None),
        axis_y=None if ranged is None else rrb.ScalarAxis(range=ranged, zoom_lock=False),
    )


def blueprint(motors: Sequence[str] = ("a", "b"), ranges: Ranges | None = None) -> rrb.Blueprint:
    """The default layout: the motors side by side, the loop timing beneath."""
    ranges = ranges or {}
    columns = []
    for m in motors:
        at, volts, title = f"motor/{m}", f"motor/{m}/voltage", f"Motor {m.upper()}"
        everything_but_voltage = ["$origin/**", "- $origin/voltage"]
        speed = plot(f"{title}: speed (rad/s)", at, ranges.get(at), everything_but_voltage)
        voltage = plot(f"{title}: voltage (V)", volts, ranges.get(volts), legend=None)
        columns.append(rrb.Vertical(speed, voltage, row_shares=[3, 2]))
    timing = plot("Loop timing (µs)", "loop", ranges.get("loop"), legend="RightTop")
    return collapsed(rrb.Vertical(rrb.Horizontal(*columns), timing, row_shares=[3, 1]))


def collapsed(layout: rrb.Container) -> rrb.Blueprint:
    """``layout`` with the side panels collapsed, on the ``time`` timeline."""
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="time"),
    )


def span_of(extremes: Mapping[str, Range], paths: Iterable[str], **kwargs: float) -> Range | None:
    """:func:`padded_range` over the (min, max) recorded of those ``paths`` that have one."""
    seen = [extremes[p] for p in paths if p in extremes]
    if not seen:
        return None
    return padded_range(min(lo for lo, _ in seen), max(hi for _, hi in seen), **kwargs)


def data_ranges(extremes: Mapping[str, Range], motors: Sequence[str]) -> dict[str, Range | None]:
    """The plots' ranges from entity path → (min, max) recorded, with 10 % to spare."""
    speeds = [kind for kind in _MOTOR_SERIES if kind != "voltage"]
    ranges = {f"motor/{m}": span_of(extremes, [f"motor/{m}/{s}" for s in speeds]) for m in motors}
    ranges |= {f"motor/{m}/voltage": span_of(extremes, [f"motor/{m}/voltage"]) for m in motors}
    ranges["loop"] = span_of(extremes, [f"loop/{name}" for name in _LOOP_SERIES], min_span=10.0)
    return ranges


GPIO_ROOT = "gpio"
CART_ROOT = "cart"


def channels_blueprint(float_labels: Sequence[str], int_labels: Sequence[str]) -> rrb.Blueprint:
    """The monitor's layout: float channels above int channels, the cart's messages beneath."""
    floats = _channels_view("Float channels", float_labels)
    ints = _channels_view("Int channels", int_labels)
    texts = rrb.TextLogView(name="Cart messages", origin=f"/{CART_ROOT}")
    return collapsed(rrb.Vertical(floats, ints, texts, row_shares=[3, 2, 1]))


def _channels_view(
    name: str, labels: Sequence[str], ranged: Range | None = None
) -> rrb.TimeSeriesView:
    return plot(name, GPIO_ROOT, ranged, [f"$origin/{label}" for label in labels])


_SPEED_KINDS = ("reference", "speed", "estimate", "true_speed")
# a monitor label that names a motor's signal (``speedA`` too) → the run's entity of that signal
_RUN_ENTITY = {label_key(f"{kind}_{m}"): f"motor/{m}/{kind}"
               for m in ("a", "b") for kind in (*_SPEED_KINDS, "voltage")}  # fmt: skip


def _natural(label: str) -> list[object]:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", label)]


def review_styles(paths: Iterable[str]) -> dict[str, SeriesStyle]:
    """Entity path → the run's style for the paths whose labels name a motor's signals
    (``gpio/speed_a`` drawn as ``motor/a/speed``), in label order."""
    gpio = sorted({path for path in paths if path.startswith(f"{GPIO_ROOT}/")})
    run = {path: _RUN_ENTITY.get(label_key(path.removeprefix(f"{GPIO_ROOT}/"))) for path in gpio}
    return {path: STYLES[entity] for path, entity in run.items() if entity is not None}


def review_blueprint(
    extremes: Mapping[str, Range], whole: Collection[str], paths: Collection[str]
) -> rrb.Blueprint:
    """The layout ``cartctl review`` gives a recording of entity ``paths``, with y ranges from
    entity path → (min, max): a run's (``motor/...``); a monitor's built from its labels
    (``gpio/...``); other series' (:func:`figures_blueprint`); the run's plain layout otherwise.

    A monitor's labels that name a motor's signals (``speedA`` too) get the run's arrangement;
    the other channels follow, fractions in one plot and the ``whole``-number paths in another;
    then the cart's messages when the recording has texts.
    """
    if motors := sorted(motors_in(paths)):
        return blueprint(motors, data_ranges(extremes, motors))
    labels = sorted((p.removeprefix(f"{GPIO_ROOT}/") for p in extremes
                     if p.startswith(f"{GPIO_ROOT}/")), key=_natural)  # fmt: skip
    if not labels:
        return figures_blueprint(extremes, paths) or blueprint()
    run = {label: _RUN_ENTITY.get(label_key(label), "") for label in labels}

    def view(name: str, chosen: list[str], margin: float = 0.1) -> rrb.TimeSeriesView:
        entities = [f"{GPIO_ROOT}/{label}" for label in chosen]
        return _channels_view(name, chosen, span_of(extremes, entities, margin=margin))

    columns = []
    for m in ("a", "b"):
        speeds = [
            label for label in labels if run[label].removeprefix(f"motor/{m}/") in _SPEED_KINDS
        ]
        voltages = [label for label in labels if run[label] == f"motor/{m}/voltage"]
        plots = []
        if speeds:
            plots.append(view(f"Motor {m.upper()}: speed (rad/s)", speeds, SPEED_MARGIN))
        if voltages:
            plots.append(view(f"Motor {m.upper()}: voltage (V)", voltages))
        if plots:
            columns.append(rrb.Vertical(*plots, row_shares=[3, 2][: len(plots)]))
    rows: list[tuple[float, rrb.Container | rrb.View]] = []  # (share, view)
    if columns:
        rows.append((6, rrb.Horizontal(*columns)))
    rest = [label for label in labels if not run[label]]
    fractions = [label for label in rest if f"{GPIO_ROOT}/{label}" not in whole]
    counts = [label for label in rest if f"{GPIO_ROOT}/{label}" in whole]
    for name, chosen, share in (("Channels", fractions, 2), ("Whole-number channels", counts, 1.5)):
        if chosen:
            rows.append((share, view(name, chosen)))
    if any(p.startswith(f"{CART_ROOT}/") for p in paths):
        rows.append((1.5, rrb.TextLogView(name="Cart messages", origin=f"/{CART_ROOT}")))
    return collapsed(rrb.Vertical(*(v for _, v in rows), row_shares=[s for s, _ in rows]))


def figures_blueprint(
    extremes: Mapping[str, Range], paths: Collection[str]
) -> rrb.Blueprint | None:
    """Series neither a run's nor a monitor's (a commissioning stage's figures,
    ``identification/a/simulated``): a plot of each parent's series, and the stage's note
    (``commission/...``); None without such series."""
    groups: dict[str, list[str]] = {}
    for path in sorted(extremes, key=_natural):
        if "/" in path and path.split("/")[0] not in ("motor", "loop"):
            groups.setdefault(path.rpartition("/")[0], []).append(path)
    if not groups:
        return None
    plots = []
    for parent, chosen in groups.items():
        contents = [path.replace(parent, "$origin", 1) for path in chosen]
        plots.append(plot(parent, parent, span_of(extremes, chosen), contents))
    if not any(p.startswith("commission/") for p in paths):
        return collapsed(rrb.Grid(*plots))
    note = rrb.TextDocumentView(name="Note", origin="/commission")
    return collapsed(rrb.Vertical(rrb.Grid(*plots), note, row_shares=[3, 1]))
