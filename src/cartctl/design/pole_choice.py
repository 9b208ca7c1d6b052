"""Which closed-loop poles: from a settling time and overshoot, or given, and checked.

Used by :func:`cartctl.design.poles.design_poles`. A specification gives the dominant pair,
ζ = −ln(OS) / √(π² + ln²(OS)) and ζ ω_n = 4 / T_s (2 % settling), mapped by z = exp(s Ts), and
fast real poles z_j = exp(−(ratio + j) ζ ω_n Ts) for the rest. Given poles are checked: the right
number, finite, inside the unit circle, complex ones with their conjugates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import InputError

__all__ = ["check_poles", "has_repeats", "poles_text", "spec_poles"]

_REPEAT_TOL = 1e-8
"""Poles closer than this (relative) count as repeated: ``place`` cannot take them."""


def spec_poles(
    count: int,
    period_s: float,
    settling_time_s: float,
    overshoot_percent: float,
    fast_pole_ratio: float,
) -> list[complex]:
    """The dominant pair for a settling time and overshoot, then ``count − 2`` fast real poles.

    See the module docstring for the rule. Raises InputError for an overshoot outside (0, 100) %,
    a settling time shorter than ``count`` ticks (deadbeat, the fastest a discrete loop of this
    order settles), a pair oscillating beyond Nyquist, or a ratio below 1.
    """
    os_ = float(overshoot_percent)
    if not (math.isfinite(os_) and 0.0 < os_ < 100.0):
        raise InputError(f"overshoot_percent must lie strictly between 0 and 100, got {os_}")
    ts = float(settling_time_s)
    if not (math.isfinite(ts) and ts >= count * period_s):
        raise InputError(
            f"settling_time_s must be at least {count} ticks ({count * period_s:g} s), the "
            f"deadbeat time of a loop with {count} poles; got {settling_time_s}"
        )
    ratio = float(fast_pole_ratio)
    if not (math.isfinite(ratio) and ratio >= 1.0):
        raise InputError(f"fast_pole_ratio must be a number >= 1, got {fast_pole_ratio}")
    log_os = math.log(os_ / 100.0)
    zeta = -log_os / math.hypot(math.pi, log_os)
    sigma = 4.0 / ts  # ζ ω_n (1/s)
    omega_d = sigma / zeta * math.sqrt(1.0 - zeta * zeta)
    if omega_d * period_s >= math.pi:
        raise InputError(
            f"{os_:g} % overshoot with a {ts:g} s settling time oscillates beyond the Nyquist "
            "frequency; ask for less overshoot or a longer settling time"
        )
    pair = complex(math.exp(-sigma * period_s), 0.0) * complex(
        math.cos(omega_d * period_s), math.sin(omega_d * period_s)
    )
    fast = [complex(math.exp(-(ratio + j) * sigma * period_s)) for j in range(count - 2)]
    return [pair, pair.conjugate(), *fast]


def check_poles(poles: Sequence[complex], count: int, what: str) -> list[complex]:
    """Validate the requested poles; return them with exact conjugate pairs."""
    p = [complex(v) for v in poles]
    p = [complex(v.real, 0.0) if abs(v.imag) <= 1e-12 * max(1.0, abs(v)) else v for v in p]
    if len(p) != count:
        raise InputError(f"{what} needs {count} closed-loop poles, got {len(p)}")
    for v in p:
        if not (math.isfinite(v.real) and math.isfinite(v.imag)):
            raise InputError(f"pole {v} is not a finite number")
        if abs(v) >= 1.0:
            raise InputError(
                f"pole {v:.6g} lies on or outside the unit circle (|z| = {abs(v):.6g}); a stable "
                "discrete loop needs |z| < 1"
            )
    upper = sorted((v for v in p if v.imag > 0.0), key=lambda v: (v.real, v.imag))
    lower = sorted((v.conjugate() for v in p if v.imag < 0.0), key=lambda v: (v.real, v.imag))
    if len(upper) != len(lower) or any(
        abs(a - b) > 1e-9 * max(1.0, abs(a)) for a, b in zip(upper, lower, strict=True)
    ):
        raise InputError(
            f"complex poles must come in conjugate pairs, got {[f'{v:.6g}' for v in p]}"
        )
    out = [v for v in p if v.imag == 0.0]
    for v in upper:
        out += [v, v.conjugate()]
    return sorted(out, key=lambda v: (abs(v), v.imag))


def poles_text(poles: Sequence[complex] | NDArray[np.inexact]) -> str:
    """Poles on one line: ``0.999998, 0.5±0.2j``."""
    parts = []
    for p in poles:
        z = complex(p)
        if abs(z.imag) < 1e-9:
            parts.append(f"{z.real:.6g}")
        elif z.imag > 0:
            parts.append(f"{z.real:.6g}±{z.imag:.3g}j")
    return ", ".join(parts)


def has_repeats(poles: Sequence[complex]) -> bool:
    return any(
        abs(a - b) <= _REPEAT_TOL * max(1.0, abs(a))
        for i, a in enumerate(poles)
        for b in poles[i + 1 :]
    )
