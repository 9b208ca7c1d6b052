"""A ``.rrd`` recording read back (:func:`read_recording`) and streamed with the project's layout
(:func:`stream`) into a fresh stream (:func:`new_stream`) of any viewer."""

from __future__ import annotations

import uuid
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from cartctl.errors import DataFileError, MissingFileError

if TYPE_CHECKING:  # rerun takes ~0.6 s to import: only the review itself loads it
    import numpy as np
    import rerun as rr
    import rerun.blueprint as rrb
    from numpy.typing import NDArray
    from rerun.chunk import Chunk, RrdReader, StoreEntry

LOAD_TIMEOUT_S = 30.0  # longest wait for a viewer to take in (or show) the whole recording

# series made from a recording, to stream with it: entity path → (time (s), tick, values)
Series = Mapping[str, tuple["NDArray[np.float64]", "NDArray[np.float64]", "NDArray[np.float64]"]]


def read_recording(path: Path) -> tuple[RrdReader, StoreEntry]:
    """Open a ``.rrd`` file and find its (first) recording."""
    from rerun.chunk import RrdReader

    if path.is_dir():
        raise DataFileError(path, "is a directory; expected a Rerun recording (.rrd)")
    if not path.is_file():
        raise MissingFileError(path, "recording")
    if path.stat().st_size == 0:
        raise DataFileError(path, "the file is empty; expected a Rerun recording (.rrd)")
    try:
        reader = RrdReader(path)
        entries = reader.recordings()
    except (RuntimeError, ValueError, OSError) as exc:
        raise DataFileError(path, f"not a readable Rerun recording ({exc})") from None
    if not entries:
        raise DataFileError(path, "holds no recording (a blueprint file?)")
    return reader, entries[0]


def stream(
    reader: RrdReader, entry: StoreEntry, rec: rr.RecordingStream, *, extra: Series | None = None
) -> dict[str, int]:
    """Send the layout (:func:`layout`), every chunk of the recording, then ``extra`` (the
    smoothed speed, styled) into ``rec``; waits until sent. Returns the last time on each
    timeline (ns for durations, the index for sequences)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    ends: dict[str, int] = {}
    chunks = list(reader.stream(store=entry))
    for chunk in chunks:
        if chunk.is_static or chunk.is_empty:
            continue
        batch = chunk.to_record_batch()
        for name in chunk.timeline_names:
            last = pc.max(batch.column(name).cast(pa.int64())).as_py()
            if last is not None:
                ends[name] = max(ends.get(name, last), last)
    rec.send_blueprint(layout(chunks))
    rec.send_chunks(chunks)
    _restyle(chunks, rec)
    _send_extra(extra or {}, rec)
    rec.flush(timeout_sec=LOAD_TIMEOUT_S)
    return ends


SCALARS = "Scalars:scalars"


def scalar_stats(chunks: Iterable[Chunk]) -> tuple[dict[str, tuple[float, float]], set[str]]:
    """Per entity path of scalar series: the lowest and highest finite value, and the set of
    paths whose values are all whole numbers."""
    import numpy as np
    import pyarrow.compute as pc

    extremes: dict[str, tuple[float, float]] = {}
    fractional: set[str] = set()
    for chunk in chunks:
        if chunk.is_static or chunk.is_empty:
            continue
        batch = chunk.to_record_batch()
        if SCALARS not in batch.schema.names:
            continue
        values = pc.list_flatten(batch.column(SCALARS)).to_numpy(zero_copy_only=False)
        values = values[np.isfinite(values)]
        if not values.size:
            continue
        path = chunk.entity_path.lstrip("/")
        lo, hi = float(values.min()), float(values.max())
        old = extremes.get(path, (lo, hi))
        extremes[path] = (min(old[0], lo), max(old[1], hi))
        if np.any(values != np.round(values)):
            fractional.add(path)
    return extremes, set(extremes) - fractional


def _send_extra(extra: Series, rec: rr.RecordingStream) -> None:
    from cartctl.sinks.rerun_sink import send_series

    for entity, (time_s, tick, values) in extra.items():
        send_series(rec, entity, time_s, tick, values)


def _restyle(chunks: Sequence[Chunk], rec: rr.RecordingStream) -> None:
    """A monitor's motor signals drawn in the run's colours (the review's stream only)."""
    import rerun as rr

    from cartctl.sinks.channels_rerun import GPIO_ROOT, review_styles

    prefix = f"{GPIO_ROOT}/"
    labels = sorted({c.entity_path.lstrip("/").removeprefix(prefix) for c in chunks
                     if c.entity_path.lstrip("/").startswith(prefix)})  # fmt: skip
    for entity, style in review_styles(labels).items():
        rec.log(entity, rr.SeriesLines(colors=[style.color], widths=[style.width]), static=True)


def layout(chunks: Sequence[Chunk]) -> rrb.Blueprint:
    """The layout of a recording: the run's (``motor/...``), the monitor's built from its labels
    (``gpio/...``), each with y ranges from the values; the run's plain layout otherwise."""
    from cartctl.sinks.rerun_layout import blueprint, data_ranges

    extremes, whole = scalar_stats(chunks)
    paths = {chunk.entity_path.lstrip("/") for chunk in chunks}
    motors = sorted(
        {p.split("/")[1] for p in paths if p.startswith("motor/") and p.count("/") >= 2}
    )
    if motors:
        return blueprint(motors, data_ranges(extremes, motors))
    if any(p.startswith("gpio/") for p in extremes):
        from cartctl.sinks.channels_rerun import CART_ROOT, review_blueprint

        texts = any(p.startswith(f"{CART_ROOT}/") for p in paths)
        return review_blueprint(extremes, whole, texts=texts)
    return blueprint()


def new_stream(entry: StoreEntry) -> rr.RecordingStream:
    """A recording stream for ``entry``'s application, under a fresh recording id."""
    import rerun as rr

    # reviewing the same file twice into one viewer gives two recordings, not every row twice
    return rr.RecordingStream(
        entry.application_id, recording_id=uuid.uuid4(), send_properties=False
    )
