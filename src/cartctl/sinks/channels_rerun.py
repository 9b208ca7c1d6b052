"""The Rerun sink of ``cartctl monitor``: every column but ``time_s`` and ``tick`` is a series
under ``gpio/<label>``, with the cart's messages under ``cart/``; and review's layouts for them."""

from __future__ import annotations

import re
from collections.abc import Collection, Iterable, Mapping, Sequence
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from cartctl.data.columns import label_key
from cartctl.sinks.rerun_layout import (
    SPEED_MARGIN,
    STYLES,
    TICK_COLUMN,
    TIME_COLUMN,
    Range,
    SeriesStyle,
    collapsed,
    plot,
    span_of,
)
from cartctl.sinks.rerun_sink import RerunSink, timelines

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
    extremes: Mapping[str, Range], whole: Collection[str] = (), *, texts: bool = True
) -> rrb.Blueprint:
    """The layout ``cartctl review`` gives a monitor recording, from entity path → (min, max).

    Labels that name a motor's signals (``speedA`` too) get the run's arrangement; the other
    channels follow, fractions in one plot and the ``whole``-number paths in another; then the
    cart's messages when the recording has ``texts``.
    """
    labels = sorted((p.removeprefix(f"{GPIO_ROOT}/") for p in extremes
                     if p.startswith(f"{GPIO_ROOT}/")), key=_natural)  # fmt: skip
    run = {label: _RUN_ENTITY.get(label_key(label), "") for label in labels}

    def view(name: str, chosen: list[str], margin: float = 0.1) -> rrb.TimeSeriesView:
        paths = [f"{GPIO_ROOT}/{label}" for label in chosen]
        return _channels_view(name, chosen, span_of(extremes, paths, margin=margin))

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
    if texts:
        rows.append((1.5, rrb.TextLogView(name="Cart messages", origin=f"/{CART_ROOT}")))
    return collapsed(rrb.Vertical(*(v for _, v in rows), row_shares=[s for s, _ in rows]))


class ChannelsRerunSink(RerunSink):
    """A :class:`RerunSink` of labelled channels (the first ``float_count`` are float channels,
    the rest int channels, shown apart) and the cart's text."""

    _default_name = "cartctl monitor"

    def __init__(self, *args: Any, float_count: int = 8, **options: Any) -> None:
        super().__init__(*args, **{"batch_ticks": 20, **options})  # 20 rows a block unless told
        self.float_count = int(float_count)

    def _entities(self, columns: list[str]) -> tuple[tuple[int, str], ...]:
        return tuple(
            (i, f"{GPIO_ROOT}/{c}")
            for i, c in enumerate(columns)
            if c not in (TIME_COLUMN, TICK_COLUMN)
        )

    def _describe(self, rec: rr.RecordingStream) -> None:
        labels = [entity.removeprefix(f"{GPIO_ROOT}/") for _, entity in self._signals]
        floats, ints = labels[: self.float_count], labels[self.float_count :]
        rec.send_blueprint(channels_blueprint(floats, ints))
        for label in labels:
            rec.log(f"{GPIO_ROOT}/{label}", rr.SeriesLines(names=[label]), static=True, strict=True)
        rr.TextLog.columns(text=[""], level=["INFO"])

    def log_text(
        self, entity: str, text: str, time_s: float, tick: int, level: str = "INFO"
    ) -> None:
        """One line of text (a ``TextLog``) at a time and tick; never raises unless ``strict``."""
        rec = self._recording
        if rec is None or self._closed:
            return
        try:
            rec.send_columns(
                entity,
                indexes=timelines([time_s], [tick]),
                columns=rr.TextLog.columns(text=[text], level=[level]),
                strict=True,
            )
        except Exception as exc:
            self._problem(f"logging text to {entity} failed: {exc}", raise_now=True)
