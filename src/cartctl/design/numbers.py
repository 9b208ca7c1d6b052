"""Numbers as the design command prints them: 3 significant figures, noise shown as 0.

One rule for the terminal and the figures of ``cartctl design``: every value with the same number
of significant figures (``0.59, 0.405`` rather than ``0.59, 0.4049``), and a value below
``ZERO_FRACTION`` of its scale (the largest value it is shown with, or 1) printed as ``0``, so a
steady-state error of 3.6e-15 rad/s reads 0 rad/s. Pure text, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

__all__ = ["ZERO_FRACTION", "db", "sig", "sig_list"]

ZERO_FRACTION = 1e-9
"""A value below this fraction of its scale is floating-point noise: printed as 0."""


def sig(value: float | None, digits: int = 3, *, scale: float = 1.0, none: str = "—") -> str:
    """``value`` with ``digits`` significant figures; 0 below ``ZERO_FRACTION``·``scale``.

    Parameters
    ----------
    value : float or None
    digits : int
        Significant figures, trailing zeros kept (``1.40``).
    scale : float
        The magnitude the value is compared with (default 1: absolute).
    none : str
        Shown for None (and NaN).
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return none
    v = float(value)
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    if abs(v) < ZERO_FRACTION * max(abs(scale), 1e-300):
        return "0"
    text = f"{v:#.{digits}g}"  # '#' keeps trailing zeros: 1.40, not 1.4
    mantissa, _, exponent = text.partition("e")
    return mantissa.rstrip(".") + (f"e{exponent}" if exponent else "")


def sig_list(values: Iterable[float], digits: int = 3) -> str:
    """Comma-separated values, each with ``digits`` significant figures, noise against the
    largest of them shown as 0."""
    vals = [float(v) for v in values]
    scale = max((abs(v) for v in vals), default=1.0) or 1.0
    return ", ".join(sig(v, digits, scale=scale) for v in vals)


def db(value_db: float, decimals: int = 2) -> str:
    """A level in dB with fixed ``decimals``; a value that rounds to zero is ``0.00``, not
    ``-0.00`` (|T| = 1 − 1e-8 at 0 Hz reads 0.00 dB)."""
    text = f"{value_db:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text
