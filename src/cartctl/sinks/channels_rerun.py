"""A Rerun sink for arbitrary labelled channels (``cartctl monitor``), plus the cart's text.

:class:`ChannelsRerunSink` is the :class:`~cartctl.sinks.rerun_sink.RerunSink` (same modes, viewer
start, batching thread, ``send_columns`` on the ``time`` and ``tick`` timelines, problem reporting)
with another mapping: every column other than ``time_s`` and ``tick`` is one scalar series under
``gpio/<column>``, and the layout shows the float channels in one time-series view, the int
channels in another, and the cart's messages (``cart/print``, ``cart/events``) in a text log.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

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
    padded_range,
)
from cartctl.sinks.rerun_sink import RerunSink

GPIO_ROOT = "gpio"
CART_ROOT = "cart"


def channels_blueprint(float_labels: Sequence[str], int_labels: Sequence[str]) -> rrb.Blueprint:
    """The monitor's layout: float channels above int channels, the cart's messages beneath.

    Parameters
    ----------
    float_labels, int_labels : sequence of str
        Labels of the channels, i.e. the entities ``gpio/<label>`` of each view.

    Returns
    -------
    rerun.blueprint.Blueprint
    """
    floats = rrb.TimeSeriesView(
        name="Float channels",
        origin=f"/{GPIO_ROOT}",
        contents=[f"$origin/{label}" for label in float_labels],
        plot_legend=rrb.PlotLegend(corner="RightBottom", visible=True),
    )
    ints = rrb.TimeSeriesView(
        name="Int channels",
        origin=f"/{GPIO_ROOT}",
        contents=[f"$origin/{label}" for label in int_labels],
        plot_legend=rrb.PlotLegend(corner="RightBottom", visible=True),
    )
    texts = rrb.TextLogView(name="Cart messages", origin=f"/{CART_ROOT}")
    return rrb.Blueprint(
        rrb.Vertical(floats, ints, texts, row_shares=[3, 2, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="time"),
    )


_SPEED_KINDS = ("reference", "speed", "estimate", "true_speed")


def _natural(label: str) -> list[object]:
    """Sort key: FloatIn2 before FloatIn10."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", label)]


def review_styles(labels: Sequence[str]) -> dict[str, SeriesStyle]:
    """The run's line styles (colour, width) for the labels that name a motor's signals.

    Entity path → style, e.g. ``gpio/speed_a`` drawn as the run draws ``motor/a/speed``. The
    labels stay the legend's names.
    """
    styles: dict[str, SeriesStyle] = {}
    for label in labels:
        for m in ("a", "b"):
            for kind in (*_SPEED_KINDS, "voltage"):
                if label_key(label) == label_key(f"{kind}_{m}"):
                    styles[f"{GPIO_ROOT}/{label}"] = STYLES[f"motor/{m}/{kind}"]
    return styles


def review_blueprint(
    extremes: Mapping[str, Range], whole: Collection[str] = (), *, texts: bool = True
) -> rrb.Blueprint:
    """The layout ``cartctl review`` gives a monitor recording, built from its labels.

    Labels that name a motor's signals (``speed_a``, ``reference_a``, ``estimate_a``,
    ``voltage_a``; case and separators aside, so ``speedA`` too) get the run's arrangement: per
    motor, speed with reference and estimate above the voltage. The other channels follow, those
    with fractions in one plot and those holding whole numbers only (int channels, counters) in
    another; the cart's messages beneath. Every plot's y range spans its values.

    Parameters
    ----------
    extremes : mapping of str to (float, float)
        Entity path (``gpio/<label>``) → the lowest and highest value recorded.
    whole : collection of str
        The entity paths whose values are all whole numbers.
    texts : bool
        Whether the recording holds the cart's messages (``cart/...``).
    """
    labels = sorted((p.removeprefix(f"{GPIO_ROOT}/") for p in extremes
                     if p.startswith(f"{GPIO_ROOT}/")), key=_natural)  # fmt: skip
    taken: set[str] = set()

    def pick(keys: Sequence[str]) -> list[str]:
        wanted = {label_key(k) for k in keys}
        hits = [label for label in labels if label_key(label) in wanted and label not in taken]
        taken.update(hits)
        return hits

    def view(name: str, chosen: list[str], margin: float = 0.1) -> rrb.TimeSeriesView:
        seen = [extremes[f"{GPIO_ROOT}/{label}"] for label in chosen]
        lo, hi = min(v[0] for v in seen), max(v[1] for v in seen)
        return rrb.TimeSeriesView(
            name=name,
            origin=f"/{GPIO_ROOT}",
            contents=[f"$origin/{label}" for label in chosen],
            plot_legend=rrb.PlotLegend(corner="RightBottom", visible=True),
            axis_y=rrb.ScalarAxis(range=padded_range(lo, hi, margin=margin), zoom_lock=False),
        )

    columns = []
    for m in ("a", "b"):
        speeds = pick([f"{k}_{m}" for k in _SPEED_KINDS])
        voltages = pick([f"voltage_{m}"])
        plots = []
        if speeds:
            plots.append(view(f"Motor {m.upper()}: speed (rad/s)", speeds, SPEED_MARGIN))
        if voltages:
            plots.append(view(f"Motor {m.upper()}: voltage (V)", voltages))
        if plots:
            columns.append(rrb.Vertical(*plots, row_shares=[3, 2][: len(plots)]))
    rows: list[rrb.Container | rrb.View] = []
    shares: list[float] = []
    if columns:
        rows.append(rrb.Horizontal(*columns))
        shares.append(6)
    rest = [label for label in labels if label not in taken]
    fractions = [label for label in rest if f"{GPIO_ROOT}/{label}" not in whole]
    counts = [label for label in rest if f"{GPIO_ROOT}/{label}" in whole]
    for name, chosen in (("Channels", fractions), ("Whole-number channels", counts)):
        if chosen:
            rows.append(view(name, chosen))
            shares.append(2 if name == "Channels" else 1.5)
    if texts:
        rows.append(rrb.TextLogView(name="Cart messages", origin=f"/{CART_ROOT}"))
        shares.append(1.5)
    return rrb.Blueprint(
        rrb.Vertical(*rows, row_shares=shares),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="time"),
    )


class ChannelsRerunSink(RerunSink):
    """Streams labelled channels and the cart's text to a Rerun recording (file and/or viewer).

    Parameters
    ----------
    mode, path, connect_url, batch_ticks, strict
        As for :class:`~cartctl.sinks.rerun_sink.RerunSink`.
    float_count : int
        How many of the value columns (after ``time_s`` and ``tick``) are float channels; the rest
        are int channels (they only go to different views).
    recording_name : str, optional
        Name shown in the viewer; defaults to the file's stem.
    """

    def __init__(
        self,
        mode: str = "save",
        path: str | Path | None = None,
        *,
        float_count: int = 8,
        recording_name: str | None = None,
        connect_url: str | None = None,
        batch_ticks: int = 20,
        strict: bool = False,
    ) -> None:
        super().__init__(mode, path, recording_name=recording_name or (
            Path(path).stem if path is not None else "cartctl monitor"
        ), connect_url=connect_url, batch_ticks=batch_ticks, strict=strict)  # fmt: skip
        self.float_count = int(float_count)

    def _entities(self, columns: list[str]) -> tuple[tuple[int, str], ...]:
        """Every column but ``time_s`` and ``tick`` is a channel, under ``gpio/<label>``."""
        return tuple(
            (i, f"{GPIO_ROOT}/{c}")
            for i, c in enumerate(columns)
            if c not in (TIME_COLUMN, TICK_COLUMN)
        )

    def _describe(self, rec: rr.RecordingStream) -> None:
        """Floats and ints in their own views, one series per label; text logs warmed up."""
        labels = [entity.removeprefix(f"{GPIO_ROOT}/") for _, entity in self._signals]
        floats, ints = labels[: self.float_count], labels[self.float_count :]
        rec.send_blueprint(channels_blueprint(floats, ints))
        for label in labels:
            rec.log(f"{GPIO_ROOT}/{label}", rr.SeriesLines(names=[label]), static=True,
                    strict=True)  # fmt: skip
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
                indexes=[
                    rr.TimeColumn("time", duration=[time_s]),
                    rr.TimeColumn("tick", sequence=[tick]),
                ],
                columns=rr.TextLog.columns(text=[text], level=[level]),
                strict=True,
            )
        except Exception as exc:
            self._problem(f"logging text to {entity} failed: {exc}", raise_now=True)
