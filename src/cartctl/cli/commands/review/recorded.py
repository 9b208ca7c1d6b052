"""``review``'s smoothed speed: of a CSV trace (its metrics) and of a ``.rrd`` recording (its
metrics, and the series streamed into the viewer with the recording).

The choices (when, which model) are :mod:`cartctl.cli.commands.review.smoothed`'s. A run's recording
may already hold its smoothed speed (``motor/<m>/smoothed_speed``, made by ``run``): its metrics
are then taken from it, unless ``--model`` asks for another model.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cartctl.cart import PERIOD_S
from cartctl.cli.commands.review.recording import Series, read_recording
from cartctl.cli.commands.review.smoothed import (
    add_smoothed,
    recorded_model,
    recorded_model_of,
    recording_columns,
    trace_hints,
    wanted,
)
from cartctl.data.read import read_trace
from cartctl.design.smoother import METHOD
from cartctl.errors import DataWarning
from cartctl.sinks.summary import add_smoothed_metrics, format_summary, trace_metrics

TIMING_COLUMNS = ("period_error_us", "compute_us")


def smooth_csv(
    summary: dict[str, Any],
    path: str | Path,
    mapping: Mapping[str, str] | None,
    model: str | None,
) -> dict[str, Any]:
    """A CSV trace's summary with the smoothed metrics, where wanted (changed and returned).

    The model: ``model`` (``--model``; a problem with it is an error), else the one named in
    the run's recording beside the trace (``RUN.rrd``), else that of the controller its meta file's
    command ran, else none (a note says so). A trace of the serial path (its meta file says) gets
    them beside the true speed too.
    """
    serial, run_model, extra = trace_hints(path)
    if not wanted(summary, serial_path=serial, asked=model is not None):
        return summary
    if model is None:
        model_path = recorded_model_of(Path(path).with_suffix(".rrd")) or run_model
    else:
        model_path, extra = model, 0
    with warnings.catch_warnings():  # csv_summary has read it once and said what it found
        warnings.simplefilter("ignore", DataWarning)
        trace = read_trace(path, mapping)
    add_smoothed(summary, trace.columns(), trace.period_s, model_path,
                 extra_delay_ticks=extra, strict=model is not None)  # fmt: skip
    return summary


def recording_summary(path: Path, model: str | None) -> tuple[str, Series | None]:
    """The metrics table of a run's recording, with the smoothed metrics, and the smoothed series
    to stream with it (None when the recording has them, or none were made).

    A recording without motors (a monitor's) gives ``("", None)``.
    """
    reader, entry = read_recording(path)
    chunks = list(reader.stream(store=entry))
    columns = recording_columns(chunks)
    if not columns:
        return "", None
    time_s = columns["time_s"]
    steps = np.diff(time_s[np.isfinite(time_s)])
    period_s = float(np.round(np.median(steps), 6)) if steps.size else PERIOD_S
    zeros = np.zeros(time_s.size)
    columns = {**dict.fromkeys(TIMING_COLUMNS, zeros), **columns}
    summary = trace_metrics(columns, period_s)
    summary["recording"] = str(path)
    extra: Series | None = None
    recorded = {m: columns[f"smoothed_speed_{m}"] for m in summary["motors"]
                if f"smoothed_speed_{m}" in columns}  # fmt: skip
    if recorded and model is None:
        add_smoothed_metrics(summary, columns, recorded, period_s)
        summary["smoothed"] = {"model": recorded_model(chunks), "method": METHOD}
    elif wanted(summary, asked=model is not None):
        model_path = model if model is not None else recorded_model(chunks)
        speeds = add_smoothed(summary, columns, period_s, model_path, strict=model is not None)
        extra = {
            f"motor/{m}/smoothed_speed": (time_s, columns["tick"], speed)
            for m, speed in speeds.items()
        }
    return format_summary(summary), extra
