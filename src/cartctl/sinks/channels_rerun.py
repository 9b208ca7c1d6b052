"""The Rerun sink of ``cartctl monitor``: every column but ``time_s`` and ``tick`` is a series
under ``gpio/<label>``, with the cart's messages under ``cart/``."""

from __future__ import annotations

from typing import Any

import rerun as rr

from cartctl.sinks.rerun_layout import GPIO_ROOT, TICK_COLUMN, TIME_COLUMN, channels_blueprint
from cartctl.sinks.rerun_sink import RerunSink, timelines


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
