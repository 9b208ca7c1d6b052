"""One Rerun recording (``.rrd``) per commissioning stage: its series and a note of its figures.

A stage's recording holds its series on the ``time`` timeline (duration, s) and the stage's
figures as a Markdown document at ``commission/<stage>``. A trace (the checks, the excitation)
goes under the run's Rerun entity paths (``motor/a/voltage``, ``motor/a/speed`` …) with the run's
layout (:func:`cartctl.sinks.rerun_layout.blueprint`), so ``cartctl review`` shows it as a run.
Recording problems never stop commissioning: they come back as text for the summary.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from cartctl.data.trace import Trace
from cartctl.sinks.rerun_layout import ENTITY_PATHS, blueprint
from cartctl.sinks.rerun_problems import file_failure
from cartctl.sinks.rerun_sink import APPLICATION_ID

Series = Mapping[str, tuple[NDArray[np.float64], NDArray[np.float64]]]
"""Entity path → (time s, values)."""


def trace_series(trace: Trace) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """A trace's columns under the run's Rerun entity paths."""
    t = np.asarray(trace.time_s, dtype=float)
    return {ENTITY_PATHS[c]: (t, np.asarray(v, dtype=float))
            for c, v in trace.columns().items() if c in ENTITY_PATHS}  # fmt: skip


def record_stage(path: Path, series: Series, note: str, stage: str, *,
                 layout: bool = False) -> str | None:  # fmt: skip
    """Write ``series`` and ``note`` (Markdown) to ``path``; with ``layout``, the run's layout.

    Returns a problem's description, or None.
    """
    try:
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        path.parent.mkdir(parents=True, exist_ok=True)
        rec.set_sinks(rr.FileSink(path))
        rec.send_recording_name(path.stem)
        if layout:
            rec.send_blueprint(blueprint(("a", "b"), None))
        rec.log(f"commission/{stage}", rr.TextDocument(note, media_type=rr.MediaType.MARKDOWN),
                static=True)  # fmt: skip
        for entity, (time_s, values) in series.items():
            rec.send_columns(entity, indexes=[rr.TimeColumn("time", duration=np.asarray(time_s))],
                             columns=rr.Scalars.columns(scalars=np.asarray(values, float)))  # fmt: skip
        rec.flush(timeout_sec=5.0)
        rec.disconnect()
    except Exception as exc:  # the SDK's failures: commissioning goes on, the summary says so
        return f"{path}: {file_failure(exc, path) or exc}"  # the SDK's own log lines are off
    return None
