"""Numbers for the terminal: one rounding per table column, the unit in the column's header.

The tables of ``run``, ``review`` and ``tune`` print each column with one number of decimals,
chosen so that the column's largest magnitude (or a larger scale the caller gives, such as the
RMS error for the steady-state error beside it) has :data:`SIG_FIGS` significant figures. Smaller
values of the column then show fewer significant figures, never more; a value far below the
scale (3.6e-15 rad/s next to 0.79 rad/s) rounds to 0 and prints as a zero of the column's
precision, without a sign. A magnitude of 1000 or more is rounded to tens (1234 → 1230). Light:
no numpy, so the parser's modules may import it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

SIG_FIGS = 3
"""Significant figures of a column's largest magnitude."""

MAX_DECIMALS = 6
"""The most decimals a column gets (a column of tiny values without a scale)."""

MISSING = "—"
"""How a missing (None or NaN) value prints."""


def _finite(values: Iterable[float | None]) -> list[float]:
    return [abs(float(v)) for v in values if v is not None and math.isfinite(v)]


def column_decimals(
    values: Iterable[float | None],
    *,
    sig: int = SIG_FIGS,
    scale: float | None = None,
    max_decimals: int = MAX_DECIMALS,
) -> int:
    """Decimals that give the column's largest magnitude ``sig`` significant figures.

    Parameters
    ----------
    values : iterable of float or None
        The column (None, NaN and infinities are left out).
    sig : int
        Significant figures of the largest magnitude.
    scale : float, optional
        A magnitude the column is measured against (its decimals are chosen for the larger of
        it and the column's largest value).
    max_decimals : int
        The most decimals returned.

    Returns
    -------
    int
        Decimals, negative to round to tens, hundreds, …; 0 for a column of zeros.
    """
    top = max(_finite([*values, scale]), default=0.0)
    if top == 0.0:
        return 0
    decimals = sig - 1 - math.floor(math.log10(top))
    if abs(round(top, decimals)) >= 10.0 ** (sig - decimals):  # 9.996 rounds up to 10.0
        decimals -= 1
    return min(decimals, max_decimals)


def format_fixed(value: float | None, decimals: int) -> str:
    """``value`` rounded to ``decimals`` (negative: to tens, …); '—' for None or NaN, '∞' for
    an infinity; a value that rounds to zero prints without a sign."""
    if value is None or math.isnan(value):
        return MISSING
    if math.isinf(value):
        return "∞" if value > 0 else "−∞"
    rounded = round(float(value), decimals)
    if rounded == 0.0:
        rounded = 0.0  # no '-0.000'
    return f"{rounded:.{max(decimals, 0)}f}"


def format_column(
    values: Sequence[float | None],
    *,
    sig: int = SIG_FIGS,
    scale: float | None = None,
    factor: float = 1.0,
    max_decimals: int = MAX_DECIMALS,
) -> list[str]:
    """The cells of one column: every value with the column's decimals (:func:`column_decimals`).

    ``factor`` converts the values first (1e3: s to ms); ``scale`` is in the printed unit.
    """
    shown = [None if v is None else float(v) * factor for v in values]
    decimals = column_decimals(shown, sig=sig, scale=scale, max_decimals=max_decimals)
    return [format_fixed(v, decimals) for v in shown]


def exact_decimals(values: Iterable[float], max_decimals: int = MAX_DECIMALS) -> int:
    """The fewest decimals (up to ``max_decimals``) that print every value exactly (grid settings
    as the user gave them: 0.04, 0.10, 0.16)."""
    for decimals in range(max_decimals + 1):
        if all(abs(round(v, decimals) - v) <= 1e-9 * max(1.0, abs(v)) for v in values):
            return decimals
    return max_decimals


def render_table(
    headers: Sequence[str],
    rows: Sequence[Sequence[str]],
    *,
    left: Sequence[int] = (0,),
    gap: int = 2,
    indent: str = "",
) -> list[str]:
    """Lines of a table: each column as wide as its header or widest cell, right-aligned (the
    columns in ``left`` left-aligned), ``gap`` spaces between columns."""
    widths = [max([len(h), *(len(r[i]) for r in rows)]) for i, h in enumerate(headers)]

    def line(cells: Sequence[str]) -> str:
        parts = [c.ljust(w) if i in left else c.rjust(w)
                 for i, (c, w) in enumerate(zip(cells, widths, strict=True))]  # fmt: skip
        return (indent + (" " * gap).join(parts)).rstrip()

    return [line(headers), *(line(r) for r in rows)]
