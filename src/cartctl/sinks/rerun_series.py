"""Series made after a run from all its rows (the smoothed speed), into its Rerun recording."""

from __future__ import annotations

import atexit
from collections.abc import Mapping, Sequence

import numpy as np
import rerun as rr
from numpy.typing import ArrayLike

from cartctl.sinks.rerun_layout import STYLES
from cartctl.sinks.rerun_sink import RerunSink

Series = Mapping[str, tuple[ArrayLike, ArrayLike | None, ArrayLike]]  # path: (time, tick, values)


def send_series(
    rec: rr.RecordingStream,
    entity: str,
    time_s: ArrayLike,
    tick: ArrayLike | None,
    values: ArrayLike,
) -> None:
    """One whole series under ``entity`` (in its :data:`STYLES` style) on the ``time`` (s) and
    ``tick`` timelines; ``tick`` None numbers the values from 0."""
    y = np.asarray(values, dtype=float)
    ticks = np.arange(y.size) if tick is None else np.asarray(tick)
    style = STYLES.get(entity)
    if style is not None:
        rec.log(entity, rr.SeriesLines(colors=[style.color], names=[style.name],
                                       widths=[style.width]), static=True)  # fmt: skip
    rec.send_columns(
        entity,
        indexes=[
            rr.TimeColumn("time", duration=np.asarray(time_s, dtype=float)),
            rr.TimeColumn("tick", sequence=ticks.astype(np.int64)),
        ],
        columns=rr.Scalars.columns(scalars=y),
        strict=True,
    )


class HeldRerunSink(RerunSink):
    """The run's :class:`RerunSink` kept open after the loop's ``close`` for :meth:`send_extra`,
    until :meth:`release` (or the interpreter's exit) closes it."""

    _released = False

    def open(self, columns: Sequence[str]) -> None:
        super().open(columns)
        atexit.register(self.release)

    def close(self) -> None:
        if self._released:
            super().close()
        else:
            self._send_rows()

    def release(self) -> None:
        atexit.unregister(self.release)
        self._released = True
        self.close()

    def send_extra(self, series: Series, texts: Mapping[str, str] | None = None) -> None:
        """Send whole series (:func:`send_series`) and static texts (what they were made from)."""
        rec = self._recording
        if rec is None or self._closed:
            return
        try:
            for entity, (time_s, tick, values) in series.items():
                send_series(rec, entity, time_s, tick, values)
            for entity, text in (texts or {}).items():
                rec.log(entity, rr.TextDocument(text), static=True)
        except Exception as exc:
            self._problem(f"sending what was made from the run failed: {exc}", raise_now=True)


def warm_up() -> None:
    """Pay the Rerun SDK's first-use cost (pyarrow importing pandas, 0.15 s) with a throw-away
    blueprint before a cart is connected, not between the loop-delay probe and the first tick."""
    from cartctl.sinks.rerun_layout import blueprint

    blueprint(("a", "b"))
