"""Facts of the MECOtron cart that every layer uses, defined once: supply, encoder, period."""

from __future__ import annotations

import math

from cartctl.errors import InputError

SUPPLY_V = 12.0
"""The cart's supply voltage: every command saturates at ± this value (V)."""
ENCODER_COUNTS_PER_REV = 1792
"""Encoder counts per wheel revolution."""
PERIOD_S = 0.01
"""The control thread's period on the cart (s)."""
PWM_STEP_V = SUPPLY_V / 255.0
"""One step of the H-bridges' 8-bit PWM (V): 47 mV."""


def encoder_quantum_rad_s(
    period_s: float = PERIOD_S, counts_per_rev: int = ENCODER_COUNTS_PER_REV
) -> float:
    """One encoder count per tick, the resolution of a measured speed (rad/s):
    q = 2π / counts_per_rev / Ts, 0.3506 rad/s at the cart's 10 ms."""
    if not (math.isfinite(period_s) and period_s > 0.0):
        raise InputError(f"the period must be a positive number of seconds, got {period_s}")
    return 2.0 * math.pi / counts_per_rev / period_s


def nk_fits_loop_delay(nk: int, loop_delay_ticks: int) -> bool:
    """Whether a model with input delay ``nk`` describes a loop of ``loop_delay_ticks``: nk =
    delay + 1 (the report's timing: the command lands the tick after its measurement) or nk =
    delay (it lands within the tick, and the tick's average speed already sees part of it)."""
    return int(nk) in (int(loop_delay_ticks), int(loop_delay_ticks) + 1)


def check_voltage_limit(
    limit_v: float, name: str = "voltage limit", *, most_v: float = SUPPLY_V
) -> float:
    """``limit_v`` as a float if it is in (0, ``most_v``] V (the supply, or a controller
    file's own limit); else InputError ``NAME must be in (0, MOST] V, got VALUE``."""
    try:
        value = float(limit_v)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and 0.0 < value <= most_v):
        raise InputError(f"{name} must be in (0, {most_v:g}] V, got {limit_v}")
    return value
