"""The smoothed speed in ``run``'s summary and in ``review``: when, with which model, and where.

The numerics are :func:`cartctl.design.smoother.smooth_speed`; the metrics on its result are
:func:`cartctl.sinks.summary.add_smoothed_metrics`. Here: the choices around them.

- When: a trace whose metrics are on the measured speed (no true speed: a real cart, a CSV
  without ``true_speed_*`` columns), a run through the serial path (``virtual``, ``serial:PORT``:
  there the smoothed speed stands beside the simulator's true speed), or whenever ``review`` is
  given ``--model``.
- Which model: ``run`` takes the model its controller file was designed on; ``review`` takes
  ``--model``, else the model a ``run`` named in its ``.rrd`` beside the CSV, else the model the
  trace's meta file names (a run stores its controller and that model there). Without one the
  summary says, in one line, that the smoothed metrics need a model, and shows the encoder's.
- The loop delay: the model applies to the rows as written (the trace columns) on the loop it was
  identified on; a run whose measured loop delay is longer than the one the controller was designed
  for (its ``loop_delay_ticks``) smooths with the difference as extra input delay, as ``design``
  would.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.data.modelfile import ModelFile, load_models
from cartctl.design.smoother import METHOD, smooth_speed
from cartctl.errors import CartctlError, InputError
from cartctl.sinks.summary import add_smoothed_metrics

MODEL_ENTITY = "run/model"
"""The static text entity of a run's ``.rrd`` that names its controller's model (the smoothed
speed's); not in the layout."""

NEEDS_MODEL = "smoothed metrics: they need a model (review --model MODEL.toml); encoder only"


def wanted(summary: Mapping[str, Any], *, serial_path: bool = False, asked: bool = False) -> bool:
    """Whether a summary gets the smoothed metrics (see the module docstring)."""
    return asked or serial_path or summary.get("metrics_signal") != "true_speed"


def smoothed_speeds(
    columns: Mapping[str, NDArray[np.float64]],
    models: ModelFile,
    period_s: float,
    *,
    extra_delay_ticks: int = 0,
) -> dict[str, NDArray[np.float64]]:
    """Per motor with a reference in the trace, the smoothed speed at each row (rad/s).

    A run's trace (it has the loop's timing columns) ends with its stop row: the zero-volt
    command sent when the run ended, which acts only after the last measurement. The smoother
    holds the last tick's voltage there instead, so the smoothed speed of the last row does not
    bend towards a stop that had not happened yet (that would keep it out of the settling band).

    Raises
    ------
    InputError
        The models tick at another period than the trace; a motor without a model; a column
        with a non-finite value.
    """
    if abs(models.period_s - period_s) > 1e-9:
        raise InputError(
            f"the model is for Ts = {models.period_s} s but the trace ticks at {period_s} s"
        )
    stop_row = "period_error_us" in columns and "compute_us" in columns
    out: dict[str, NDArray[np.float64]] = {}
    for m in ("a", "b"):
        if f"reference_{m}" not in columns:
            continue
        voltage_v = np.array(columns[f"voltage_{m}"], dtype=float)
        if stop_row and voltage_v.size > 1:
            voltage_v[-1] = voltage_v[-2]
        result = smooth_speed(models.motor(m), voltage_v, columns[f"speed_{m}"],
                              extra_delay_ticks=extra_delay_ticks)  # fmt: skip
        out[m] = result.speed_rad_s
    return out


def add_smoothed(
    summary: dict[str, Any],
    columns: Mapping[str, NDArray[np.float64]],
    period_s: float,
    model_path: str | Path | None,
    *,
    extra_delay_ticks: int = 0,
    strict: bool = False,
) -> dict[str, NDArray[np.float64]]:
    """Smooth the trace and add the metrics and ``smoothed`` to the summary.

    ``summary["smoothed"]`` becomes ``{"model": path, "method": "kalman-rts",
    "extra_delay_ticks": d}``, or ``{"model": path or None, "method": ..., "note": why not}``.

    Parameters
    ----------
    strict : bool
        Raise a problem with the model (a model the user named) instead of noting it.

    Returns
    -------
    dict of str to ndarray
        The smoothed speeds per motor (empty when there are none).
    """
    entry: dict[str, Any] = {"model": None if model_path is None else str(model_path),
                             "method": METHOD}  # fmt: skip
    summary["smoothed"] = entry
    if model_path is None:
        entry["note"] = NEEDS_MODEL
        return {}
    try:
        models = load_models(model_path)
        speeds = smoothed_speeds(columns, models, period_s, extra_delay_ticks=extra_delay_ticks)
    except CartctlError as exc:
        if strict:
            raise
        entry["note"] = f"smoothed metrics: none ({exc})"
        return {}
    add_smoothed_metrics(summary, columns, speeds, period_s)
    entry["extra_delay_ticks"] = extra_delay_ticks
    return speeds


def run_extra_delay(loop_delay_ticks: int | None, designed_ticks: int | None) -> int:
    """Ticks of loop delay a run had beyond the one its controller was designed for (>= 0)."""
    if loop_delay_ticks is None or designed_ticks is None:
        return 0
    return max(0, int(loop_delay_ticks) - int(designed_ticks))


def smooth_run(
    summary: dict[str, Any],
    columns: Mapping[str, NDArray[np.float64]],
    period_s: float,
    model_path: str | Path | None,
    recording: Any = None,
) -> None:
    """``run``'s part: the smoothed metrics when wanted, and the smoothed speed in the recording.

    ``summary`` must be complete (``link``, ``loop_delay_ticks``,
    ``controller_loop_delay_ticks``). ``recording`` is the run's
    :class:`~cartctl.sinks.rerun_sink.HeldRerunSink` (or None), still open: it gets the series
    ``motor/<m>/smoothed_speed`` and the model's name, and is released here whatever happens.
    """
    try:
        speeds: dict[str, NDArray[np.float64]] = {}
        if wanted(summary, serial_path=bool(summary.get("link"))):
            extra = run_extra_delay(
                summary.get("loop_delay_ticks"), summary.get("controller_loop_delay_ticks")
            )
            speeds = add_smoothed(summary, columns, period_s, model_path, extra_delay_ticks=extra)
        if recording is not None:
            tick = columns.get("tick")
            series = {f"motor/{m}/smoothed_speed": (columns["time_s"], tick, speed)
                      for m, speed in speeds.items()}  # fmt: skip
            texts = {} if model_path is None else {MODEL_ENTITY: str(model_path)}
            recording.send_extra(series, texts)
    finally:
        if recording is not None:
            recording.release()


# -- from a recording ---------------------------------------------------------------------------


def recording_columns(chunks: Any) -> dict[str, NDArray[np.float64]]:
    """The trace columns a run's recording holds (the Rerun entity paths back to their columns),
    one row per recorded tick, with ``time_s`` and ``tick``; empty when it holds no motor.

    Parameters
    ----------
    chunks : iterable of rerun.chunk.Chunk
        The recording's chunks (:func:`cartctl.cli.commands.review.recording.read_recording`).
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    from cartctl.sinks.rerun_layout import ENTITY_PATHS

    column_of = {path: column for column, path in ENTITY_PATHS.items()}
    parts: dict[str, list[tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]]] = {}
    for chunk in chunks:
        column = column_of.get(chunk.entity_path.lstrip("/"))
        if column is None or chunk.is_static or chunk.is_empty:
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if not {"tick", "time", "Scalars:scalars"} <= set(names):
            continue
        tick = batch.column("tick").cast(pa.int64()).to_numpy(zero_copy_only=False)
        time_ns = batch.column("time").cast(pa.int64()).to_numpy(zero_copy_only=False)
        values = pc.list_element(batch.column("Scalars:scalars"), 0)
        parts.setdefault(column, []).append(
            (tick, time_ns, values.to_numpy(zero_copy_only=False).astype(float))
        )
    if "speed_a" not in parts:
        return {}
    ticks = np.unique(np.concatenate([t for chunks_ in parts.values() for t, _, _ in chunks_]))
    out: dict[str, NDArray[np.float64]] = {"tick": ticks.astype(float)}
    time_s = np.full(ticks.size, np.nan)
    for column, pieces in parts.items():
        values = np.full(ticks.size, np.nan)
        for tick, time_ns, v in pieces:
            where = np.searchsorted(ticks, tick)
            values[where] = v
            time_s[where] = time_ns / 1e9
        out[column] = values
    out["time_s"] = time_s
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


def trace_hints(trace_path: str | Path) -> tuple[bool, str | None, int]:
    """What a run trace's meta file (:mod:`cartctl.data.tracemeta`) tells the smoother.

    Returns
    -------
    serial_path : bool
        The trace came through the serial path (``virtual``, a cart on a port).
    model : str or None
        The model the run's controller was designed on, as the meta file names it; None for a
        trace whose meta file names none.
    extra_delay_ticks : int
        The run's loop delay beyond the controller's (0 when either is unknown).
    """
    from cartctl.data.tracemeta import read_trace_meta
    from cartctl.design.controllerfile import load_controller

    try:
        meta = read_trace_meta(trace_path)
    except CartctlError:
        return False, None, 0
    if meta is None:
        return False, None, 0
    serial = meta.plant.startswith(("virtual", "cart on"))
    if not meta.controller:  # an excitation, or a run from an older cartctl
        return serial, meta.model or None, 0
    try:
        design = load_controller(meta.controller)
    except (CartctlError, OSError):
        return serial, meta.model or None, 0
    return (
        serial,
        meta.model or design.model_path,
        run_extra_delay(meta.loop_delay_ticks, design.loop_delay_ticks),
    )


def recorded_model_of(path: Path) -> str | None:
    """The model named in a recording file (a run's ``.rrd``), or None (no file, not readable,
    no model)."""
    if not path.is_file():
        return None
    try:
        from rerun.chunk import RrdReader

        reader = RrdReader(path)
        entries = reader.recordings()
        return recorded_model(reader.stream(store=entries[0])) if entries else None
    except Exception:  # an unreadable recording only means no model from it
        return None
