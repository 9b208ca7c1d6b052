"""What the terminal shows of a run: the live :class:`StatusLine`, and the run metrics from a
trace, for the ``run`` summary and ``cartctl review RUN.csv --json``: per motor the step metrics
(:mod:`cartctl.measures.stepinfo`) of the first reference step from rest, the RMS tracking error
and the largest |voltage|, judged on the true speed where the plant gives one, else the measured
speed; for the loop, timing percentiles and deadline misses (start error plus compute time beyond
the period)."""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping, Sequence
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import encoder_quantum_rad_s
from cartctl.errors import InputError, OutputError
from cartctl.link.bridge import HOST_LOSS_WARN_PERCENT, EchoDelays
from cartctl.measures.metrics import finite_or_none, percentiles
from cartctl.measures.numfmt import column_decimals, format_column, format_fixed, render_table
from cartctl.measures.stepinfo import SETTLING_FRACTION, first_step, step_info

Array = NDArray[np.float64]
Columns = Mapping[str, Array]  # a trace's columns by name

SIGNALS = {"true_speed": "the true speed", "speed": "the measured speed"}
ROW_LABELS = {"true_speed": "true", "speed": "encoder"}


def motor_metrics(
    time_s: Array, reference: Array, speed: Array, voltage: Array, *, settling_floor: float = 0.0
) -> dict[str, Any]:
    """``run --json`` entry of one motor, judging ``speed`` (rad/s) in a settling band of
    max(2 % of the step, ``settling_floor``); step metrics None without a step from rest (a
    speed at its onset of half the step or more: a trace begun after it)."""
    keys = ("overshoot_percent", "settling_time_s", "rise_time_s", "steady_state_error")
    out: dict[str, Any] = dict.fromkeys(keys)
    rms = float(np.sqrt(np.mean((reference - speed) ** 2))) if speed.size else None
    out["rms_error"] = finite_or_none(rms)  # no speed: step_info's InputError below
    magnitude = np.abs(voltage)
    out["max_abs_voltage"] = finite_or_none(float(np.max(magnitude))) if magnitude.size else None
    span = first_step(reference, initial=0.0)  # the loop starts from rest
    if span is not None and span[0] < speed.size:  # half way at the onset: begun mid-run
        span = span if 2 * abs(speed[span[0]]) < abs(reference[span[0]]) else None
    if span is not None:
        start, end = span
        info = step_info(time_s[:end], speed[:end], reference=float(reference[start]), initial=0.0,
                         onset_s=float(time_s[start]), settling_floor=settling_floor)  # fmt: skip
        out.update({key: finite_or_none(getattr(info, key)) for key in keys})
    return out


def timing_metrics(period_error_us: Array, compute_us: Array, period_s: float) -> dict[str, Any]:
    """Percentiles of the period error and compute time (µs), and the deadline misses."""
    misses = int(np.count_nonzero(period_error_us + compute_us > period_s * 1e6))
    return {"deadline_misses": misses, "period_error_us": percentiles(period_error_us),
            "compute_us": percentiles(compute_us)}  # fmt: skip


def metrics_signal(columns: Columns) -> str:
    """'true_speed' when every motor of the trace has a finite true-speed column, else 'speed'."""
    motors = [m for m in ("a", "b") if f"reference_{m}" in columns]
    true = [columns.get(f"true_speed_{m}") for m in motors]
    if motors and all(c is not None and np.all(np.isfinite(c)) for c in true):
        return "true_speed"
    return "speed"


def trace_metrics(columns: Columns, period_s: float) -> dict[str, Any]:
    """The whole summary (without file names) from trace columns (a closed-loop trace's)."""
    for name in ("time_s", "reference_a", "speed_a", "voltage_a", "period_error_us", "compute_us"):
        if name not in columns:
            raise InputError(f"the trace has no '{name}' column: it is not a closed-loop run trace")
    t = columns["time_s"]
    signal = metrics_signal(columns)
    return {
        "ticks": int(t.size),
        "duration_s": float(t[-1] - t[0]) if t.size else 0.0,  # a run of N ticks: N·Ts
        **timing_metrics(columns["period_error_us"], columns["compute_us"], period_s),
        "metrics_signal": signal,
        "settling_band": {
            "fraction": SETTLING_FRACTION,
            "floor_rad_s": encoder_quantum_rad_s(period_s),
        },
        "motors": {
            m: _judged(columns, m, columns[f"{signal}_{m}"], period_s)
            for m in ("a", "b")
            if f"reference_{m}" in columns
        },
    }


def _judged(columns: Columns, m: str, speed: Array, period_s: float) -> dict[str, Any]:
    """:func:`motor_metrics` of motor ``m`` on ``speed``, settling within one encoder count."""
    time_s, reference, voltage = (columns[k] for k in ("time_s", f"reference_{m}", f"voltage_{m}"))
    return motor_metrics(
        time_s, reference, speed, voltage, settling_floor=encoder_quantum_rad_s(period_s)
    )


def add_smoothed_metrics(
    summary: dict[str, Any], columns: Columns, speeds_rad_s: Columns, period_s: float
) -> None:
    """Add each motor's metrics on its smoothed speed (rad/s, per row) to a
    :func:`trace_metrics` summary, as ``motors.<m>.smoothed``, in the same settling band."""
    for m, speed in speeds_rad_s.items():
        if m in summary["motors"]:
            summary["motors"][m]["smoothed"] = _judged(columns, m, speed, period_s)


MOTOR_METRICS: tuple[tuple[str, str, str, str, float, int, bool], ...] = (
    # key, label in the summary, in a comparison, unit, scale, a comparison's decimals, whether
    # (B − A)/|A| means something: overshoot is already a percentage (its difference is in
    # points) and the steady-state error is signed (a ratio across zero misleads)
    ("overshoot_percent", "overshoot", "overshoot", "%", 1.0, 2, False),
    ("rise_time_s", "rise", "rise time 10–90 %", "ms", 1e3, 1, True),
    ("settling_time_s", "settling", "settling time", "ms", 1e3, 1, True),
    ("steady_state_error", "ss error", "steady-state error", "rad/s", 1.0, 3, False),
    ("rms_error", "rms error", "rms error", "rad/s", 1.0, 3, True),
    ("max_abs_voltage", "max |V|", "max |voltage|", "V", 1.0, 2, True),
)


def motor_table(motors: Mapping[str, Mapping[str, Any]], indent: str = "  ") -> list[str]:
    """The per-motor table: units in the headers, one rounding per column; the steady-state
    error is rounded like the RMS error, so a numerical zero prints as 0.000."""
    errors = ("steady_state_error", "rms_error")  # one precision for the two, both in rad/s
    error_decimals = column_decimals(entry.get(k) for entry in motors.values() for k in errors)
    cells: list[list[str]] = []
    for key, _, _, _, scale, _, _ in MOTOR_METRICS:
        values = [entry.get(key) for entry in motors.values()]
        if key in errors:
            cells.append([format_fixed(v, error_decimals) for v in values])
        else:
            cells.append(format_column(values, factor=scale))
    rows = [[m, *(c[i] for c in cells)] for i, m in enumerate(motors)]
    headers = [f"{label} ({unit})" for _, label, _, unit, *_ in MOTOR_METRICS]
    return render_table(["motor", *headers], rows, indent=indent)


def timing_text(summary: Mapping[str, Any]) -> str:
    """Period error and compute time percentiles (µs), or that the clock was simulated."""
    pe, cu = summary["period_error_us"], summary["compute_us"]
    if pe.get("max") == 0.0 and cu.get("p99") == 0.0:  # a simulated clock: no time passed
        return "timing: simulated clock, no real-time figures"
    period, compute = ("/".join(format_column([x.get(k) for k in ("p50", "p99", "max")]))
                       for x in (pe, cu))  # fmt: skip
    return f"period error p50/p99/max {period} µs; compute p50/p99/max {compute} µs"


def format_summary(summary: Mapping[str, Any]) -> str:
    if summary.get("trace_kind") == "monitor":
        timing = "no loop timing (a monitor trace: the cart ran its own loop)"
    else:
        timing = f"deadline misses {summary['deadline_misses']}; {timing_text(summary)}"
    lines = [f"{summary['ticks']} ticks, {summary['duration_s']:.2f} s; {timing}"]
    band = summary["settling_band"]
    lines.append(
        f"  tracking on {SIGNALS[summary['metrics_signal']]}, settling band "
        f"max({band['fraction'] * 100:g} %, {band['floor_rad_s']:.3g} rad/s)"
    )
    lines += smoothed_lines(summary)
    link = summary.get("link")
    delay, designed = summary.get("loop_delay_ticks"), summary.get("controller_loop_delay_ticks")
    if not link and (delay is not None or designed is not None):
        lines.append(
            f"  loop delay {'—' if delay is None else delay} tick(s); the controller is designed "
            f"for {'—' if designed is None else designed}"
        )
    if link:
        shown = "—"
        if delay is not None:
            echo = link["echo_delay_ticks"]
            shown = f"{delay} ticks (echo {echo}; the report's model: nk = {delay + 1})"
        if designed is not None:
            shown += f", the controller is designed for {designed}"
        lines.append(
            f"  link {link['port']}: loop delay {shown}; {link['frames']} frames, "
            f"{link['crc_errors']} CRC errors, {link['garbage_bytes']} garbage bytes, "
            f"{link['lost_frames']} frames lost, {link['missed_ticks']} cart ticks missed, "
            f"{link['skipped_ticks']} skipped by the host, {link['watchdog_trips']} watchdog trips"
        )
        lines.append("  " + host_loss_text(link))
        lines += delay_seen_lines(link)
    incomplete = summary.get("incomplete") or {}
    for key in ("trace", "recording"):
        if summary.get(key):
            why = incomplete.get(summary[key])
            lines.append(f"  {key}: {summary[key]}" + (f" (INCOMPLETE: {why})" if why else ""))
    return "\n".join(lines)


def smoothed_lines(summary: Mapping[str, Any]) -> list[str]:
    """The motor table; with smoothed metrics, two labelled rows a motor and their model."""
    motors = summary["motors"]
    smoothed = summary.get("smoothed") or {}
    note = [f"  {smoothed['note']}"] if smoothed.get("note") else []  # why none (for a motor)
    if not any("smoothed" in e for e in motors.values()):
        return [*motor_table(motors), *note]
    label = ROW_LABELS.get(summary.get("metrics_signal", "speed"), "encoder")
    rows: dict[str, Mapping[str, Any]] = {}
    for m, entry in motors.items():
        rows[f"{m} {label}"] = entry
        if "smoothed" in entry:
            rows[f"{m} smoothed"] = entry["smoothed"]
    return [
        f"  smoothed: the speed by a Kalman RTS smoother over the trace with the model "
        f"{smoothed.get('model')} and the recorded voltages",
        *motor_table(rows),
        *note,
    ]


def host_loss_text(link: Mapping[str, Any]) -> str:
    """``commands lost on the way to the cart: n of N (x %)``, marked when beyond 1 %."""
    lost, sent = link.get("host_frames_lost", 0), link.get("host_frames_sent", 0)
    percent = link.get("host_frames_lost_percent", 0.0)
    text = f"commands lost on the way to the cart: {lost} of {sent} ({percent:.1f} %)"
    if percent > HOST_LOSS_WARN_PERCENT:
        text += " — more than 1 %: the cart held older voltages at those ticks"
    return text


def delay_seen_lines(link: Mapping[str, Any]) -> list[str]:
    def spread(counts: Mapping[str, int] | None) -> str:
        return EchoDelays.of({int(d): n for d, n in (counts or {}).items()}).describe()

    if "loop_delay_ticks_seen" not in link:  # not a run's link (a monitor's)
        return []
    probe = link.get("loop_delay_probe")
    lines = [
        f"  loop delay seen over the run: {spread(link.get('loop_delay_ticks_seen'))}"
        + ("" if probe is None else f"; the probe before it: {spread(probe.get('counts'))}")
    ]
    if link.get("loop_delay_change"):
        lines.append("  " + link["loop_delay_change"])
    return lines


def warn_delay_change(link: Mapping[str, Any] | None, command: str) -> None:
    """One line on stderr when the loop delay changed during the run."""
    if link and link.get("loop_delay_change"):
        print(f"cartctl {command}: warning: {link['loop_delay_change']}", file=sys.stderr)


def warn_host_losses(link: Mapping[str, Any] | None, command: str) -> None:
    """One line on stderr when more than 1 % of the host's frames never reached the cart."""
    if link and link.get("host_frames_lost_percent", 0.0) > HOST_LOSS_WARN_PERCENT:
        print(f"cartctl {command}: warning: {host_loss_text(link)}", file=sys.stderr)


def mark_incomplete(summary: dict[str, Any], incomplete: Sequence[OutputError]) -> None:
    """Set ``trace_complete``, ``recording_complete`` (None without one) and ``incomplete``."""
    short = {str(e.path): e.detail for e in incomplete}
    summary["incomplete"] = short
    summary["trace_complete"] = summary["trace"] not in short
    recording = summary.get("recording")
    summary["recording_complete"] = None if recording is None else recording not in short


class StatusLine:
    """A sink that rewrites one terminal line every ``every_s`` of run time, from ``idle`` (so the
    tick pays nothing); a tick is a miss when its start error and compute time pass ``period_s``."""

    def __init__(self, stream: TextIO, *, period_s: float, every_s: float = 0.25) -> None:
        self.stream = stream
        self.period_s = float(period_s)
        self.every_ticks = max(1, round(every_s / period_s))
        self._row: Sequence[float] | None = None
        self._index: dict[str, int] = {}
        self._misses = 0
        self._since = 0
        self._shown = False

    def open(self, columns: Sequence[str]) -> None:
        self._index = {name: i for i, name in enumerate(columns)}

    def write(self, row: Sequence[float]) -> None:
        self._row = row
        self._since += 1
        i, j = self._index.get("period_error_us"), self._index.get("compute_us")
        if i is not None and j is not None and row[i] + row[j] > self.period_s * 1e6:
            self._misses += 1

    def idle(self) -> None:
        if self._row is None or self._since < self.every_ticks:
            return
        self._since = 0
        self.stream.write("\r" + self.line() + "\x1b[K")  # then clear to the end of the line
        self.stream.flush()
        self._shown = True

    def line(self) -> str:
        row, at = self._row, self._index
        if row is None:
            return ""

        def value(name: str) -> float:
            return row[at[name]] if name in at else math.nan

        parts = [f"t {value('time_s'):7.2f} s", f"tick {int(value('tick')):>6}"]
        for m in ("a", "b"):
            if f"reference_{m}" in at:
                parts.append(
                    f"{m}: r {value(f'reference_{m}'):6.2f} y {value(f'speed_{m}'):6.2f} rad/s "
                    f"u {value(f'voltage_{m}'):6.2f} V"
                )
        parts.append(f"misses {self._misses}")
        return "  ".join(parts)

    def close(self) -> None:
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False
