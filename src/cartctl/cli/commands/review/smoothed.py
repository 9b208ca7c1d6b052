"""The smoothed speed (:func:`cartctl.design.kalman.smooth_speed`) in ``run``'s summary and in
``review``: when the metrics are on the measured speed, through the serial path, or asked for
(``--model``); with ``--model``, else the model a run named in its ``.rrd`` or meta file (its
controller's); a run's loop delay beyond the model's own as extra input delay, as ``design``."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cartctl.cart import PERIOD_S
from cartctl.cli.commands.review.metrics import TIMING_COLUMNS, csv_summary
from cartctl.cli.commands.review.recording import read_recording, scalar_series
from cartctl.data.modelfile import ModelFile, load_models
from cartctl.data.read import read_trace
from cartctl.design.kalman import METHOD, smooth_speed
from cartctl.errors import CartctlError, InputError
from cartctl.sinks.summary import (
    Array,
    Columns,
    add_smoothed_metrics,
    format_summary,
    trace_metrics,
)

if TYPE_CHECKING:
    from cartctl.sinks.rerun_sink import Series

MODEL_ENTITY = "run/model"  # the text entity of a run's .rrd naming its model (not in the layout)

NEEDS_MODEL = "smoothed metrics: they need a model (review --model MODEL.toml); encoder only"


def wanted(summary: Mapping[str, Any], *, serial_path: bool = False, asked: bool = False) -> bool:
    """Whether a summary gets the smoothed metrics (see the module docstring)."""
    return asked or serial_path or summary.get("metrics_signal") != "true_speed"


def smoothed_speeds(
    columns: Columns, models: ModelFile, period_s: float, *, extra_delay_ticks: int = 0
) -> dict[str, Array]:
    """Per motor with a reference in the trace and a model, the smoothed speed at each row (rad/s).

    A run's trace ends with its stop row, the zero-volt command sent at the end, which acts only
    after the last measurement: the smoother holds the last tick's voltage there instead, so the
    last row does not bend towards a stop that had not happened yet.
    """
    if abs(models.period_s - period_s) > 1e-9:
        raise InputError(
            f"the model is for Ts = {models.period_s} s but the trace ticks at {period_s} s"
        )
    stop_row = "period_error_us" in columns and "compute_us" in columns
    out: dict[str, Array] = {}
    for m in (m for m in ("a", "b") if f"reference_{m}" in columns and m in models.motors):
        voltage_v = np.array(columns[f"voltage_{m}"], dtype=float)
        if stop_row and voltage_v.size > 1:
            voltage_v[-1] = voltage_v[-2]
        out[m] = smooth_speed(
            models.motor(m), voltage_v, columns[f"speed_{m}"], extra_delay_ticks=extra_delay_ticks
        ).speed_rad_s
    return out


def add_smoothed(
    summary: dict[str, Any],
    columns: Columns,
    period_s: float,
    model_path: str | Path | None,
    *,
    loop_delay_ticks: int | None = None,
    strict: bool = False,
) -> dict[str, Array]:
    """Smooth the trace, add the metrics and ``summary["smoothed"]`` (``{"model", "method",
    "extra_delay_ticks"}``, or ``{"model", "method", "note": why not}``); returns the speeds per
    motor. The ticks of the run's ``loop_delay_ticks`` beyond the model's are extra input delay. ``strict``: raise a problem with the model (one the user named) instead of noting it."""
    model = None if model_path is None else str(model_path)
    entry: dict[str, Any] = {"model": model, "method": METHOD}
    summary["smoothed"] = entry
    if model_path is None:
        entry["note"] = NEEDS_MODEL
        return {}
    try:
        models = load_models(model_path)
        extra = run_extra_delay(loop_delay_ticks, models.loop_delay_ticks)
        speeds = smoothed_speeds(columns, models, period_s, extra_delay_ticks=extra)
    except CartctlError as exc:
        if strict:
            raise
        entry["note"] = f"smoothed metrics: none ({exc})"
        return {}
    add_smoothed_metrics(summary, columns, speeds, period_s)
    unmodelled = [m for m in ("a", "b") if f"reference_{m}" in columns and m not in speeds]
    if unmodelled:  # a model file of the other motor only
        entry["note"] = (
            f"smoothed metrics: none for motor {', '.join(unmodelled)} ({model} has no model for it)"
        )
    entry["extra_delay_ticks"] = extra
    return speeds


def run_extra_delay(loop_delay_ticks: int | None, model_ticks: int | None) -> int:
    """Ticks of loop delay a run had beyond the one its model was fitted in (>= 0)."""
    if loop_delay_ticks is None or model_ticks is None:
        return 0
    return max(0, int(loop_delay_ticks) - int(model_ticks))


def smooth_run(
    summary: dict[str, Any],
    columns: Columns,
    period_s: float,
    model_path: str | Path | None,
    recording: Any = None,
) -> None:
    """``run``'s part: the smoothed metrics when wanted (``summary`` complete), and the series
    ``motor/<m>/smoothed_speed`` and the model's name in ``recording`` (the run's still open
    :class:`~cartctl.sinks.rerun_sink.HeldRerunSink`, or None), released here whatever happens."""
    try:
        speeds: dict[str, Array] = {}
        if wanted(summary, serial_path=bool(summary.get("link"))):
            delay = summary.get("loop_delay_ticks")
            speeds = add_smoothed(summary, columns, period_s, model_path, loop_delay_ticks=delay)
        if recording is not None:
            texts = {} if model_path is None else {MODEL_ENTITY: str(model_path)}
            recording.send_extra(_series(columns, speeds), texts)
    finally:
        if recording is not None:
            recording.release()


def _series(columns: Columns, speeds: Columns) -> Series:
    """The smoothed speeds as series to record (``motor/<m>/smoothed_speed``)."""
    tick = columns.get("tick")
    return {f"motor/{m}/smoothed_speed": (columns["time_s"], tick, v) for m, v in speeds.items()}


def recording_columns(chunks: Any) -> dict[str, Array]:
    """The trace columns a run's recording chunks hold, one row per recorded tick, with
    ``time_s`` and ``tick``; empty when it holds no motor."""
    from cartctl.sinks.rerun_layout import ENTITY_PATHS

    column_of = {path: column for column, path in ENTITY_PATHS.items()}
    ours = [chunk for chunk in chunks if chunk.entity_path.lstrip("/") in column_of]
    series = {column_of[p]: s for p, s in scalar_series(ours).items()}
    if "speed_a" not in series:
        return {}
    ticks = np.unique(np.concatenate([tick for tick, _, _ in series.values()]))
    out = {"tick": ticks.astype(float), "time_s": np.full(ticks.size, np.nan)}
    for column, (tick, time_ns, values) in series.items():
        where = np.searchsorted(ticks, tick)
        out[column] = np.full(ticks.size, np.nan)
        out[column][where] = values
        out["time_s"][where] = time_ns / 1e9
    return out


def recorded_model(chunks: Any) -> str | None:
    """The model a run named in its recording (:data:`MODEL_ENTITY`), or None."""
    for chunk in chunks:
        if chunk.entity_path.lstrip("/") != MODEL_ENTITY:
            continue
        batch = chunk.to_record_batch()
        if "TextDocument:text" in batch.schema.names:
            texts = batch.column("TextDocument:text").to_pylist()
            if texts and texts[-1]:
                return str(texts[-1][0])
    return None


def trace_hints(trace_path: str | Path) -> tuple[bool, str | None, int | None]:
    """What a run trace's meta file tells the smoother: whether it came through the serial path,
    the model its controller was designed on (or None), and its loop delay (ticks, or None)."""
    from cartctl.data.trace import read_trace_meta
    from cartctl.design.controllerfile import load_controller

    try:
        meta = read_trace_meta(trace_path)
    except CartctlError:
        meta = None
    if meta is None:
        return False, None, None
    serial = meta.plant.startswith(("virtual", "cart on"))
    try:  # no controller: an excitation, or a run from an older cartctl
        design = load_controller(meta.controller) if meta.controller else None
    except (CartctlError, OSError):
        design = None
    model = meta.model or (design.model_path if design is not None else None)
    return serial, model or None, meta.loop_delay_ticks


def recorded_model_of(path: Path) -> str | None:
    """The model named in a run's ``.rrd``, or None (no file, not readable, no model)."""
    if not path.is_file():  # without loading the Rerun SDK
        return None
    try:
        reader, entry = read_recording(path)
        return recorded_model(reader.stream(store=entry))
    except Exception:  # an unreadable recording only means no model from it
        return None


def smooth_csv(
    path: str | Path, mapping: Mapping[str, str] | None, model: str | None
) -> dict[str, Any]:
    """A CSV trace's summary (:func:`~.metrics.csv_summary`) with the smoothed metrics where
    wanted."""
    trace = read_trace(path, mapping)
    summary = csv_summary(trace, path)
    serial, run_model, delay = trace_hints(path)
    if not wanted(summary, serial_path=serial, asked=model is not None):
        return summary
    # the meta file is written with the trace; a recording of that name may be an earlier run's,
    # and a monitor's names no model
    recorded = summary["trace_kind"] == "run" and recorded_model_of(Path(path).with_suffix(".rrd"))
    model_path = model or run_model or recorded or None
    add_smoothed(summary, trace.columns(), trace.period_s, model_path,
                 loop_delay_ticks=delay, strict=model is not None)  # fmt: skip
    return summary


def recording_summary(path: Path, model: str | None) -> tuple[str, Series | None]:
    """The metrics table of a run's recording (``""`` for a monitor's), with the smoothed
    metrics, and the smoothed series to stream with it (None when it has them, or none made)."""
    reader, entry = read_recording(path)
    chunks = list(reader.stream(store=entry))
    columns = recording_columns(chunks)
    if not columns:
        if model is not None:
            raise InputError(
                f"--model: {path} is not a run's recording (a monitor's or a commissioning "
                "stage's): it has no metrics to smooth (a monitor's CSV trace takes --model)"
            )
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
        extra = _series(columns, speeds)
    return format_summary(summary), extra
