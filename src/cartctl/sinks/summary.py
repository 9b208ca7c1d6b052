"""Run metrics, from a trace: the ``run`` summary and ``cartctl review RUN.csv --json`` share this code.

Per motor: the step metrics of the first reference step, from rest to the reference's first
non-zero level and until its next change (10–90 % rise, overshoot, settling, steady-state
error), the RMS tracking error over the whole run and the largest |voltage|. For the
loop: period error and compute time percentiles, and deadline misses (a tick whose start error
plus compute time passes the period).

The tracking metrics are measured on the **true speed** (the ``true_speed_a/b`` columns) where
the plant gives one (the simulators), else on the measured speed; ``metrics_signal`` says which
('true_speed' or 'speed'). Settling is judged in a band of max(2 % of the step, one encoder
count per tick = 2π/1792/Ts, 0.3506 rad/s at 10 ms): a measured speed cannot resolve less.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import InputError
from cartctl.link.bridge import HOST_LOSS_WARN_PERCENT
from cartctl.metrics import finite_or_none
from cartctl.stepinfo import SETTLING_FRACTION, encoder_quantum_rad_s, step_info

SIGNALS = {"true_speed": "the true speed", "speed": "the measured speed"}
"""``metrics_signal`` values and how the summary text names them."""


def motor_metrics(
    time_s: NDArray[np.float64],
    reference: NDArray[np.float64],
    speed: NDArray[np.float64],
    voltage: NDArray[np.float64],
    *,
    settling_floor: float = 0.0,
) -> dict[str, Any]:
    """Contract-3 ``run`` entry of one motor (step metrics None when the reference has no step).

    ``speed`` is the signal judged (rad/s); the settling band is max(2 % of the step,
    ``settling_floor``) (rad/s).
    """
    out: dict[str, Any] = {
        "overshoot_percent": None,
        "settling_time_s": None,
        "rise_time_s": None,
        "steady_state_error": None,
        "rms_error": finite_or_none(float(np.sqrt(np.mean((reference - speed) ** 2))))
        if speed.size
        else None,
        "max_abs_voltage": finite_or_none(float(np.max(np.abs(voltage)))) if voltage.size else None,
    }
    initial = 0.0  # the loop starts from rest: the first step is the first departure from 0
    moved = np.flatnonzero(np.abs(reference - initial) > 1e-9)
    if moved.size == 0:
        return out
    start = int(moved[0])
    changes = np.flatnonzero(np.abs(np.diff(reference[start:])) > 1e-9)
    end = start + int(changes[0]) + 1 if changes.size else reference.size
    target = float(reference[start])
    if end - start < 5:
        return out
    info = step_info(time_s[:end], speed[:end], reference=target, initial=initial,
                     onset_s=float(time_s[start]), settling_floor=settling_floor)  # fmt: skip
    out.update(
        overshoot_percent=finite_or_none(info.overshoot_percent),
        settling_time_s=finite_or_none(info.settling_time_s),
        rise_time_s=finite_or_none(info.rise_time_s),
        steady_state_error=finite_or_none(info.steady_state_error),
    )
    return out


def timing_metrics(
    period_error_us: NDArray[np.float64], compute_us: NDArray[np.float64], period_s: float
) -> dict[str, Any]:
    """Percentiles of the period error and compute time (µs), and the deadline misses."""
    if period_error_us.size == 0:
        return {"deadline_misses": 0, "period_error_us": {"p50": None, "p99": None, "max": None},
                "compute_us": {"p50": None, "p99": None, "max": None}}  # fmt: skip
    misses = int(np.count_nonzero(period_error_us + compute_us > period_s * 1e6))
    return {
        "deadline_misses": misses,
        "period_error_us": {
            "p50": float(np.percentile(period_error_us, 50)),
            "p99": float(np.percentile(period_error_us, 99)),
            "max": float(np.max(period_error_us)),
        },
        "compute_us": {
            "p50": float(np.percentile(compute_us, 50)),
            "p99": float(np.percentile(compute_us, 99)),
            "max": float(np.max(compute_us)),
        },
    }


def metrics_signal(columns: Mapping[str, NDArray[np.float64]]) -> str:
    """'true_speed' when every motor of the trace has a finite true-speed column, else 'speed'."""
    motors = [m for m in ("a", "b") if f"reference_{m}" in columns]
    true = [columns.get(f"true_speed_{m}") for m in motors]
    if motors and all(c is not None and np.all(np.isfinite(c)) for c in true):
        return "true_speed"
    return "speed"


def trace_duration_s(time_s: NDArray[np.float64]) -> float:
    """A trace's duration (s): from its first row's time to its last's.

    A run of N ticks ends with its stop row at N·Ts, so this is the duration asked for; ``run``
    and ``review`` report the same figure for the same trace.
    """
    return float(time_s[-1] - time_s[0]) if time_s.size else 0.0


def trace_metrics(columns: Mapping[str, NDArray[np.float64]], period_s: float) -> dict[str, Any]:
    """The whole summary (without file names) from trace columns (contract 1 + closed loop)."""
    for name in ("time_s", "reference_a", "speed_a", "voltage_a", "period_error_us", "compute_us"):
        if name not in columns:
            raise InputError(f"the trace has no '{name}' column: it is not a closed-loop run trace")
    t = columns["time_s"]
    signal = metrics_signal(columns)
    quantum = encoder_quantum_rad_s(period_s)
    out = {
        "ticks": int(t.size),
        "duration_s": trace_duration_s(t),
        **timing_metrics(columns["period_error_us"], columns["compute_us"], period_s),
        "metrics_signal": signal,
        "settling_band": {"fraction": SETTLING_FRACTION, "floor_rad_s": quantum},
        "motors": {
            m: motor_metrics(
                t,
                columns[f"reference_{m}"],
                columns[f"{signal}_{m}"],
                columns[f"voltage_{m}"],
                settling_floor=quantum,
            )
            for m in ("a", "b")
            if f"reference_{m}" in columns
        },
    }
    return out


def format_summary(summary: Mapping[str, Any]) -> str:
    """A short table for the terminal."""

    def ms(x: float | None) -> str:
        return "—" if x is None else f"{x * 1e3:.0f} ms"

    def num(x: float | None, fmt: str) -> str:
        return "—" if x is None else format(x, fmt).replace("-0.000", "0.000")

    pe, cu = summary["period_error_us"], summary["compute_us"]
    if pe.get("max") == 0.0 and cu.get("p99") == 0.0:  # a virtual clock: no time passed
        timing = "timing: virtual clock, no real-time figures"
    else:
        timing = (
            f"period error p50/p99/max {num(pe['p50'], '.0f')}/{num(pe['p99'], '.0f')}/"
            f"{num(pe['max'], '.0f')} µs; compute p50/p99/max {num(cu['p50'], '.0f')}/"
            f"{num(cu['p99'], '.0f')}/{num(cu.get('max'), '.0f')} µs"
        )
    lines = [
        f"{summary['ticks']} ticks, {summary['duration_s']:.2f} s; deadline misses "
        f"{summary['deadline_misses']}; {timing}",
    ]
    signal = summary.get("metrics_signal")
    if signal in SIGNALS:
        band = summary.get("settling_band") or {}
        floor = band.get("floor_rad_s")
        shown = (
            ""
            if floor is None
            else f", settling band max({band['fraction']:.0%}, {floor:.4f} rad/s)"
        )
        lines.append(f"  tracking on {SIGNALS[signal]}{shown}")
    lines += [
        f"  {'motor':<6}{'overshoot':>11}{'rise':>9}{'settling':>10}{'ss error':>10}{'rms error':>11}{'max |V|':>9}",
    ]
    for m, e in summary["motors"].items():
        lines.append(
            f"  {m:<6}{num(e['overshoot_percent'], '.2f') + ' %':>11}{ms(e['rise_time_s']):>9}"
            f"{ms(e['settling_time_s']):>10}{num(e['steady_state_error'], '.3f'):>10}"
            f"{num(e['rms_error'], '.3f'):>11}{num(e['max_abs_voltage'], '.2f'):>9}"
        )
    link = summary.get("link")
    delay, designed = summary.get("loop_delay_ticks"), summary.get("controller_loop_delay_ticks")
    if not link and (delay is not None or designed is not None):
        lines.append(
            f"  loop delay {'—' if delay is None else delay} tick(s); the controller is designed "
            f"for {'—' if designed is None else designed}"
        )
    if link:
        delay = summary.get("loop_delay_ticks")
        shown = (
            "—"
            if delay is None
            else f"{delay} ticks (echo {link['echo_delay_ticks']}; model nk = {delay + 1})"
        )
        if designed is not None:
            shown += f", the controller is designed for {designed}"
        lines.append(
            f"  link {link['port']}: loop delay {shown}; {link['frames']} frames, "
            f"{link['crc_errors']} CRC errors, {link['garbage_bytes']} garbage bytes, "
            f"{link['lost_frames']} frames lost, {link['missed_ticks']} cart ticks missed, "
            f"{link['skipped_ticks']} skipped by the host, {link['watchdog_trips']} watchdog trips"
        )
        lines.append("  " + host_loss_text(link))
    for key in ("trace", "recording"):
        if summary.get(key):
            lines.append(f"  {key}: {summary[key]}")
    return "\n".join(lines)


def host_loss_text(link: Mapping[str, Any]) -> str:
    """``commands lost on the way to the cart: n of N (x %)``, marked when beyond 1 %."""
    lost, sent = link.get("host_frames_lost", 0), link.get("host_frames_sent", 0)
    percent = link.get("host_frames_lost_percent", 0.0)
    text = f"commands lost on the way to the cart: {lost} of {sent} ({percent:.1f} %)"
    if percent > HOST_LOSS_WARN_PERCENT:
        text += " — more than 1 %: the cart held older voltages at those ticks"
    return text


def warn_host_losses(link: Mapping[str, Any] | None, command: str) -> None:
    """One line on stderr when more than 1 % of the host's frames never reached the cart."""
    if link and link.get("host_frames_lost_percent", 0.0) > HOST_LOSS_WARN_PERCENT:
        print(f"cartctl {command}: warning: {host_loss_text(link)}", file=sys.stderr)
