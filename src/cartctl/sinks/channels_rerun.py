"""A Rerun sink for arbitrary labelled channels (``cartctl monitor``), plus the cart's text.

:class:`ChannelsRerunSink` is the :class:`~cartctl.sinks.rerun_sink.RerunSink` (same modes, viewer
start, batching thread, ``send_columns`` on the ``time`` and ``tick`` timelines, problem reporting)
with another mapping: every column other than ``time_s`` and ``tick`` is one scalar series under
``gpio/<column>``, and the layout shows the float channels in one time-series view, the int
channels in another, and the cart's messages (``cart/print``, ``cart/events``) in a text log.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from cartctl.sinks.rerun_layout import TICK_COLUMN, TIME_COLUMN
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
