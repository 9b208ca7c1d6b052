"""The Rerun sink: the loop's rows as a ``.rrd`` recording and/or a live viewer (entity paths of
docs/architecture.md, timelines ``time`` (s) and ``tick``), :class:`HeldRerunSink`, kept open
for series made after the run, and ``cartctl monitor``'s :class:`ChannelsRerunSink`. ``write``
only keeps the row; ``idle`` sends one entity's column of the oldest full block of
``batch_ticks`` rows per call, in the loop's thread (a sending thread would hold the GIL ~100 µs
a send: compute p99 190–250 µs instead of 156–163 µs). Problems warn once at ``close``; a
``.rrd`` the SDK could not write is :class:`~cartctl.errors.OutputError`.
"""

from __future__ import annotations

import atexit
import uuid
import warnings
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
import rerun as rr
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError, OutputError
from cartctl.sinks.rerun_layout import (
    ENTITY_PATHS,
    GPIO_ROOT,
    STYLES,
    TICK_COLUMN,
    TIME_COLUMN,
    Ranges,
    blueprint,
    channels_blueprint,
    motors_in,
)
from cartctl.sinks.rerun_problems import (
    VIEWER_PORT,
    VIEWER_URL,
    RecordingError,
    RecordingWarning,
    cut_to_whole_messages,
    disconnect,
    display_available,
    file_failure,
    viewer_executable,
    viewer_reachable,
)

RERUN_MODES: Final[tuple[str, ...]] = ("save", "spawn", "connect", "off")
"""``save``: the ``.rrd`` file; ``spawn``: the file (if a path is given) and a viewer started for
the run; ``connect``: the file and a viewer already running at ``connect_url``; ``off``: nothing."""

APPLICATION_ID: Final[str] = "cartctl"

_MAX_PROBLEMS = 10  # messages kept; further problems are only counted
_FLUSH_TIMEOUT_S = 5.0  # for the SDK to hand everything to the file and the viewer


class RerunSink:
    """Streams the loop's rows to a Rerun recording (:data:`RERUN_MODES`) without stalling it.

    ``path`` (required for ``save``) is the ``.rrd`` file; ``batch_ticks`` the rows per block;
    ``strict`` raises problems instead of warning (for tests); ``ranges`` the plots' y ranges.
    ``open`` makes the slow first calls (5–20 ms) before the loop starts. Rows need ``time_s``;
    ``tick`` is used when present; columns without an entity path are ignored.
    """

    _default_name = "cartctl run"

    def __init__(
        self,
        mode: str = "save",
        path: str | Path | None = None,
        *,
        connect_url: str | None = None,
        batch_ticks: int = 10,
        strict: bool = False,
        ranges: Ranges | None = None,
    ) -> None:
        if mode not in RERUN_MODES:
            raise InputError(f"rerun mode must be one of {', '.join(RERUN_MODES)}, got '{mode}'")
        if mode == "save" and path is None:
            raise InputError("rerun mode 'save' needs a path for the .rrd file")
        if int(batch_ticks) < 1:
            raise InputError(f"batch_ticks must be at least 1, got {batch_ticks}")
        self.mode = mode
        self.path = None if path is None or mode == "off" else Path(path)
        self.connect_url = connect_url or VIEWER_URL
        self.batch_ticks = int(batch_ticks)
        self.strict = strict
        self.ranges = ranges
        self.rows_written = 0
        self._problems: list[str] = []
        self._problem_count = 0
        self._recording: rr.RecordingStream | None = None
        self._block: NDArray[np.float64] | None = None
        self._filled = 0
        # (entity, values, timelines): the full blocks' sends, oldest first, one per idle()
        self._sends: deque[tuple[str, NDArray[np.float64], list[rr.TimeColumn]]] = deque()
        self._rows: list[Sequence[float]] = []  # written, not yet in a block (see idle())
        self._time_index = 0
        self._tick_index: int | None = None
        self._signals: tuple[tuple[int, str], ...] = ()
        self._closed = False
        self._viewer: str | None = None  # the address streamed to
        self.error: OutputError | None = None  # the file could not be written (raised once)

    def open(self, columns: Sequence[str]) -> None:
        """Start the recording; OutputError when the SDK cannot write the file."""
        columns = list(columns)
        if TIME_COLUMN not in columns:
            raise InputError(f"the Rerun sink needs a '{TIME_COLUMN}' column, got {columns}")
        self._time_index = columns.index(TIME_COLUMN)
        self._tick_index = columns.index(TICK_COLUMN) if TICK_COLUMN in columns else None
        self._signals = self._entities(columns)
        if self.mode == "off":
            return
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        self._recording = rec
        sinks: list[rr.FileSink | rr.GrpcSink] = []
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(self.path))
        url = self._viewer = self._viewer_url(rec)
        if url is not None:
            sinks.append(rr.GrpcSink(url))
        try:
            if sinks:
                rec.set_sinks(*sinks)
            rec.send_recording_name(self.path.stem if self.path else self._default_name)
            self._describe(rec)
            timelines(np.zeros(1), np.zeros(1, dtype=np.int64))  # the first block's sends fast
            rr.Scalars.columns(scalars=np.zeros(1))
        except Exception as exc:  # the SDK's own failures: keep the run going without Rerun
            why = file_failure(exc, self.path)
            if why is not None:  # the file: a fault
                self._recording = None
                self.error = OutputError(self.path or "", why, rows=0)
                raise self.error from None
            self._problem(f"could not start the recording: {exc}", raise_now=True)
            return
        self._block = np.empty((self.batch_ticks, len(columns)))

    def _entities(self, columns: list[str]) -> tuple[tuple[int, str], ...]:
        return tuple((i, ENTITY_PATHS[c]) for i, c in enumerate(columns) if c in ENTITY_PATHS)

    def _describe(self, rec: rr.RecordingStream) -> None:
        motors = motors_in(entity for _, entity in self._signals) or ("a", "b")
        rec.send_blueprint(blueprint(motors, self.ranges))
        for _, entity in self._signals:
            _log_style(rec, entity)

    def write(self, row: Sequence[float]) -> None:
        """Keep one tick's values for :meth:`idle`; never calls Rerun (a bad row is skipped there)."""
        if self._block is None:
            return
        rows = self._rows
        rows.append(row)
        if self.strict or len(rows) >= 2 * self.batch_ticks:  # strict, or nobody calls idle()
            self.idle()

    def idle(self) -> None:
        """Copy the kept rows into the block; send one entity of the oldest full block."""
        block = self._block
        if block is None:
            return
        if self._rows:
            rows, self._rows = self._rows, []
            for row in rows:
                try:
                    block[self._filled] = row
                except (ValueError, TypeError) as exc:
                    self._problem(f"row {self.rows_written}: {exc}", raise_now=True)
                    continue
                self._filled += 1
                self.rows_written += 1
                if self._filled == self.batch_ticks:
                    self._queue(block)
                    self._block = block = np.empty_like(block)
                    self._filled = 0
        if self._sends:
            self._send_next()

    def close(self) -> None:
        """Send the remaining rows and finish the file; safe to call again and after a failed
        ``open``. OutputError when the file is incomplete; RecordingError on problems (strict)."""
        if self._closed:
            return
        self._send_rows()
        self._closed = True
        failed: str | None = None
        rec, self._recording = self._recording, None
        steps = {} if rec is None else {"flushing": lambda: rec.flush(timeout_sec=_FLUSH_TIMEOUT_S),
                                        "closing": rec.disconnect}  # fmt: skip
        if rec is not None and self._viewer is not None:  # bounded: a viewer may never answer
            steps = {"closing": lambda: disconnect(rec, self._viewer or "", self.path)}
        for step, call in steps.items():
            try:
                call()
            except Exception as exc:
                failed = failed or file_failure(exc, self.path)
                if failed is None:  # the viewer's side: a problem, not a fault
                    timeout = isinstance(exc, TimeoutError)
                    self._problem(str(exc) if timeout else f"{step} the recording failed: {exc}")
        self._report()
        if failed is not None:
            if self.path is not None:
                cut_to_whole_messages(self.path)
            self.error = OutputError(self.path or "", failed)
            raise self.error

    def _send_rows(self) -> None:
        if self._block is not None:
            self.idle()  # the rows kept, into the blocks
            if self._filled:
                self._queue(self._block[: self._filled].copy())
            while self._sends:
                self._send_next()
        self._block = None

    def _viewer_url(self, rec: rr.RecordingStream) -> str | None:
        """Start the viewer for ``spawn``; the gRPC address to stream to, or None."""
        if self.mode not in ("connect", "spawn"):
            return None
        url, problem = self.connect_url, None
        if self.mode == "connect":
            # The SDK waits 5 s for an unreachable viewer when the sinks are set, and at close.
            if not viewer_reachable(url):
                problem = f"no viewer is listening at {url}"
        elif not display_available():
            problem = "no display (DISPLAY/WAYLAND_DISPLAY unset): not opening the viewer"
        elif (executable := viewer_executable()) is None:
            problem = "the 'rerun' viewer executable was not found next to Python or on PATH"
        else:
            url = VIEWER_URL
            try:
                rr.spawn(port=VIEWER_PORT, connect=False, executable_path=executable, recording=rec)
                if not viewer_reachable(url):  # never raises
                    problem = f"the viewer ({executable}) did not start"
            except Exception as exc:
                problem = f"could not start the viewer ({executable}): {exc}"
        if problem is None:
            return url
        self._problem(problem, raise_now=True)
        return None

    def _queue(self, block: NDArray[np.float64]) -> None:
        """A send for each entity of a block of rows, on the block's timelines."""
        if self._tick_index is not None:
            ticks = block[:, self._tick_index].astype(np.int64)
        else:  # the rows counted so far end with this block's
            ticks = np.arange(self.rows_written - len(block), self.rows_written, dtype=np.int64)
        indexes = timelines(block[:, self._time_index], ticks)
        self._sends.extend((entity, block[:, column], indexes) for column, entity in self._signals)

    def _send_next(self) -> None:
        entity, values, indexes = self._sends.popleft()
        rec = self._recording
        if rec is None:
            return
        try:
            scalars = rr.Scalars.columns(scalars=values)
            rec.send_columns(entity, indexes=indexes, columns=scalars, strict=True)
        except Exception as exc:
            self._problem(f"sending {len(values)} rows of {entity} failed: {exc}")

    def _problem(self, message: str, *, raise_now: bool = False) -> None:
        self._problem_count += 1
        if len(self._problems) < _MAX_PROBLEMS:
            self._problems.append(message)
        if self.strict and raise_now:
            raise RecordingError(f"Rerun recording: {message}")

    def _report(self) -> None:
        if not self._problem_count:
            return
        where = f" ({self.path})" if self.path else ""
        more = self._problem_count - len(self._problems)
        text = f"Rerun recording{where}: " + "; ".join(self._problems)
        if more > 0:
            text += f"; and {more} more"
        if self.strict:
            raise RecordingError(text)
        warnings.warn(text, RecordingWarning, stacklevel=3)


def timelines(time_s: Iterable[float], ticks: Iterable[int]) -> list[rr.TimeColumn]:
    """The ``time`` (s) and ``tick`` timelines of a run of rows."""
    return [rr.TimeColumn("time", duration=time_s), rr.TimeColumn("tick", sequence=ticks)]


def _log_style(rec: rr.RecordingStream, entity: str) -> None:
    style = STYLES[entity]
    lines = rr.SeriesLines(colors=[style.color], names=[style.name], widths=[style.width])
    rec.log(entity, lines, static=True, strict=True)


Series = Mapping[str, tuple[ArrayLike, ArrayLike | None, ArrayLike]]  # path: (time, tick, values)


def send_series(rec: rr.RecordingStream, series: Series) -> None:
    """Whole series, each under its entity (in its :data:`STYLES` style) on the ``time`` (s)
    and ``tick`` timelines; a tick None numbers the values from 0."""
    for entity, (time_s, tick, values) in series.items():
        y = np.asarray(values, dtype=float)
        ticks = np.arange(y.size) if tick is None else np.asarray(tick)
        if entity in STYLES:
            _log_style(rec, entity)
        rec.send_columns(
            entity,
            indexes=timelines(np.asarray(time_s, dtype=float), ticks.astype(np.int64)),
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
            send_series(rec, series)
            for entity, text in (texts or {}).items():
                rec.log(entity, rr.TextDocument(text), static=True)
        except Exception as exc:
            self._problem(f"sending what was made from the run failed: {exc}", raise_now=True)


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


def warm_up() -> None:
    """Pay the Rerun SDK's first-use cost (pyarrow importing pandas, 0.15 s) with a throw-away
    blueprint before a cart is connected, not between the loop-delay probe and the first tick."""
    blueprint(("a", "b"))
