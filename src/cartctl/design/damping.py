"""Damping ratio and natural frequency of discrete poles, through their continuous equivalent.

A pole z of a loop sampled every Ts behaves like the continuous pole s = ln(z) / Ts (the principal
logarithm, as MATLAB's and python-control's ``damp`` take it)::

    ωn = |s|  (rad/s),   f_n = ωn / 2π  (Hz),   ζ = −Re(s) / |s|

A pole at z = 0 (a pure delay, deadbeat) has no continuous equivalent: its ζ is 1 and its
frequency infinite (``None`` in JSON). A negative real pole lands at Im(s) = π/Ts: it oscillates
at Nyquist, every other tick. A pole at z = 1 (an integrator) has f_n = 0 and no ζ (NaN). Pure:
no I/O.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Iterable
from typing import Any

__all__ = ["pole_damping", "pole_table"]


def pole_damping(pole: complex, period_s: float) -> tuple[float, float | None]:
    """(ζ, f_n in Hz) of one discrete pole (see the module docstring); f_n None for z = 0."""
    z = complex(pole)
    if z == 0:
        return 1.0, None
    s = cmath.log(z) / period_s
    wn = abs(s)
    if wn == 0.0:  # z = 1: an integrator, its ζ undefined (NaN, null in JSON)
        return math.nan, 0.0
    return -s.real / wn, wn / (2.0 * math.pi)


def pole_table(poles: Iterable[Any], period_s: float) -> list[dict[str, Any]]:
    """Per pole ``{"re", "im", "damping", "freq_hz"}`` (the ``closed_loop_pole_table`` entries).

    Parameters
    ----------
    poles : iterable of complex or [re, im]
        Discrete poles, as ``closed_loop_poles`` lists them.
    period_s : float
        Sample period Ts (s).
    """
    rows = []
    for p in poles:
        z = complex(*p) if isinstance(p, list | tuple) else complex(p)
        damping, freq_hz = pole_damping(z, period_s)
        rows.append({"re": z.real, "im": z.imag, "damping": damping, "freq_hz": freq_hz})
    return rows
