"""A ``.rrd`` recording read back and streamed, with the project's layout, into a viewer.

Every way ``cartctl review`` shows a recording (native viewer, web viewer, headless screenshot)
opens the file with :func:`read_recording`, makes a fresh stream with :func:`new_stream` and sends
the layout and the data with :func:`stream`.
"""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import TYPE_CHECKING

from cartctl.errors import DataFileError, MissingFileError

if TYPE_CHECKING:  # rerun takes ~0.6 s to import: only the review itself loads it
    import rerun as rr
    from rerun.chunk import RrdReader, StoreEntry

LOAD_TIMEOUT_S = 30.0
"""Longest wait for a viewer to take in (or show) the whole recording."""


def read_recording(path: Path) -> tuple[RrdReader, StoreEntry]:
    """Open a ``.rrd`` file and find its (first) recording.

    Raises
    ------
    MissingFileError
        No such file.
    DataFileError
        Not a readable recording, or one holding no recording store.
    """
    from rerun.chunk import RrdReader

    if not path.is_file():
        raise MissingFileError(path, "recording")
    try:
        reader = RrdReader(path)
        entries = reader.recordings()
    except (RuntimeError, ValueError, OSError) as exc:
        raise DataFileError(path, f"not a readable Rerun recording ({exc})") from None
    if not entries:
        raise DataFileError(path, "holds no recording (a blueprint file?)")
    return reader, entries[0]


def stream(reader: RrdReader, entry: StoreEntry, rec: rr.RecordingStream) -> dict[str, int]:
    """Send the layout, then every chunk of the recording, into ``rec``; waits until sent.

    Returns
    -------
    dict of str to int
        The last time on each timeline (ns for durations, the index for sequences).
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    from cartctl.sinks.rerun_layout import blueprint

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
    rec.send_blueprint(blueprint())
    rec.send_chunks(chunks)
    rec.flush(timeout_sec=LOAD_TIMEOUT_S)
    return ends


def new_stream(entry: StoreEntry) -> rr.RecordingStream:
    """A recording stream for ``entry``'s application, under a fresh recording id."""
    import rerun as rr

    # A fresh recording id: reviewing the same file twice into one viewer gives two recordings
    # rather than one with every row twice. The file's own properties chunk travels with the data.
    return rr.RecordingStream(
        entry.application_id, recording_id=uuid.uuid4(), send_properties=False
    )
