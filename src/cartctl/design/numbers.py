"""Numbers as the design command prints them (:mod:`cartctl.measures.numfmt`'s rules): 3
significant figures for a value; one number of decimals for a list (3 figures for its largest);
a value far below its scale (1.8e-15 after a 10 rad/s step) as an unsigned zero; dB with two
decimals. Pure text, no numpy.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from cartctl.measures.numfmt import format_column, format_fixed


def sig(value: float | None, digits: int = 3, *, scale: float | None = None) -> str:
    """``value`` with ``digits`` significant figures (against ``scale`` when it is larger);
    '—' for None or NaN, '∞' for an infinity."""
    if value is not None and math.isinf(value):
        return format_fixed(value, 0)
    return format_column([value], sig=digits, scale=None if scale is None else abs(scale))[0]


def sig_list(values: Iterable[float], digits: int = 3) -> str:
    """Comma-separated values with one number of decimals: ``digits`` significant figures for
    the largest magnitude."""
    return ", ".join(format_column(list(values), sig=digits))


def db(value_db: float, decimals: int = 2) -> str:
    """A level in dB with ``decimals``; a level that rounds to 0 is ``0.00``, not ``-0.00``."""
    return format_fixed(value_db, decimals)
