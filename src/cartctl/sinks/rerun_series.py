"""Series made after a run from all its rows (the smoothed speed), into its Rerun recording.

:func:`send_series` sends one whole scalar series with the project's style for its entity; ``review``
uses it for a recording it streams (:mod:`cartctl.cli.commands.review.recording`). :class:`HeldRerunSink`
is the run's sink kept open after the loop has closed it, until those series are in.
"""

from __future__ import annotations

import atexit
from collections.abc import Mapping, Sequence

import numpy as np
import rerun as rr
from numpy.typing import ArrayLike

from cartctl.sinks.rerun_layout import STYLES
from cartctl.sinks.rerun_sink import RerunSink

Series = Mapping[str, tuple[ArrayLike, ArrayLike | None, ArrayLike]]
"""Entity path → (time (s), tick or None, values), each of shape (N,)."""


def send_series(
    rec: rr.RecordingStream,
    entity: str,
    time_s: ArrayLike,
    tick: ArrayLike | None,
    values: ArrayLike,
) -> None:
    """Send ``values`` under ``entity`` on the ``time`` (s) and ``tick`` timelines.

    Parameters
    ----------
    rec : rerun.RecordingStream
    entity : str
        The entity path; its style (legend name, colour, width) comes from
        :data:`~cartctl.sinks.rerun_layout.STYLES` when it has one.
    time_s : array_like, shape (N,)
        Seconds since the start.
    tick : array_like, shape (N,), or None
        Tick numbers; None numbers the values from 0.
    values : array_like, shape (N,)
    """
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
    """A :class:`~cartctl.sinks.rerun_sink.RerunSink` whose ``close`` (the loop's) sends the rows
    but keeps the recording open for :meth:`send_extra`; :meth:`release` closes it.

    The interpreter's exit releases it too, should the caller never get there: the file is
    finished and readable whatever happens after the loop.
    """

    _released = False

    def open(self, columns: Sequence[str]) -> None:
        super().open(columns)
        atexit.register(self.release)

    def close(self) -> None:
        """Send the rows kept; the recording stays open until :meth:`release`."""
        if self._released:
            super().close()
        else:
            self._send_rows()

    def release(self) -> None:
        """Close the recording (as :meth:`RerunSink.close`); safe to call more than once."""
        atexit.unregister(self.release)
        self._released = True
        self.close()

    def send_extra(self, series: Series, texts: Mapping[str, str] | None = None) -> None:
        """Send whole series (:func:`send_series`) and static texts (what they were made from).

        A problem is recorded and reported at :meth:`release` (raised at once with ``strict``).
        """
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
    """Load what the Rerun sink's first use loads lazily, before a cart is connected.

    pyarrow imports pandas on its first array where pandas is installed (about 0.15 s here);
    done when the sink opens, that delay would fall between the loop-delay probe and the first
    command, with the cart ticking on. A throw-away blueprint of the run's layout pays for it
    (and for the SDK's own first-use work) at a time nothing waits.
    """
    from cartctl.sinks.rerun_layout import blueprint

    blueprint(("a", "b"))
