"""Numbers for the terminal: one rounding per table column, the unit in the column's header.

A column gets the decimals that give its largest magnitude (or a larger ``scale`` the caller
gives, such as the RMS error beside a steady-state error) :data:`SIG_FIGS` significant figures;
smaller values show fewer, and one far below the scale prints as an unsigned zero. 1000 and more
round to tens. No numpy: the parser's modules import it."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

SIG_FIGS = 3
MAX_DECIMALS = 6
MISSING = "—"  # a None or NaN


def column_decimals(
    values: Iterable[float | None], *, sig: int = SIG_FIGS, scale: float | None = None
) -> int:
    """Decimals giving the column's largest magnitude (or ``scale``, if larger) ``sig`` significant
    figures, at most :data:`MAX_DECIMALS`; negative to round to tens …; 0 for a column of zeros.
    None, NaN and infinities are left out."""
    top = max((abs(float(v)) for v in [*values, scale] if v is not None and math.isfinite(v)),
              default=0.0)  # fmt: skip
    if top == 0.0:
        return 0
    decimals = sig - 1 - math.floor(math.log10(top))
    if abs(round(top, decimals)) >= 10.0 ** (sig - decimals):  # 9.996 rounds up to 10.0
        decimals -= 1
    return min(decimals, MAX_DECIMALS)


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
) -> list[str]:
    """The cells of one column with the column's decimals; ``factor`` converts the values first
    (1e3: s to ms), ``scale`` is in the printed unit."""
    shown = [None if v is None else float(v) * factor for v in values]
    decimals = column_decimals(shown, sig=sig, scale=scale)
    return [format_fixed(v, decimals) for v in shown]


def exact_decimals(values: Iterable[float]) -> int:
    """The fewest decimals (up to :data:`MAX_DECIMALS`) that print every value exactly (0.04,
    0.10, 0.16)."""
    for decimals in range(MAX_DECIMALS + 1):
        if all(abs(round(v, decimals) - v) <= 1e-9 * max(1.0, abs(v)) for v in values):
            return decimals
    return MAX_DECIMALS


def render_table(
    headers: Sequence[str],
    rows: Sequence[Sequence[str]],
    *,
    left: Sequence[int] = (0,),
    gap: int = 2,
    indent: str = "",
    groups: Sequence[tuple[str, int, int]] = (),
) -> list[str]:
    """Lines of a table: each column as wide as its header or widest cell, right-aligned (the
    columns in ``left`` left-aligned), ``gap`` spaces apart; each of ``groups`` (label, first
    column, last column) prints centred on a line above its columns."""
    widths = [max([len(h), *(len(r[i]) for r in rows)]) for i, h in enumerate(headers)]

    def span(first: int, last: int) -> int:
        return sum(widths[first : last + 1]) + gap * (last - first)

    for label, first, last in groups:  # widen the group's last column to fit its label
        widths[last] += max(0, len(label) - span(first, last))

    def line(cells: Sequence[str]) -> str:
        parts = [c.ljust(w) if i in left else c.rjust(w)
                 for i, (c, w) in enumerate(zip(cells, widths, strict=True))]  # fmt: skip
        return (indent + (" " * gap).join(parts)).rstrip()

    top, at = indent, len(indent)
    for label, first, last in groups:
        start = len(indent) + sum(widths[:first]) + gap * first
        top += " " * (start - at) + label.center(span(first, last))
        at = start + span(first, last)
    return [*([top.rstrip()] if groups else []), line(headers), *(line(r) for r in rows)]


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A Markdown table of text cells (``summary.md``); a '|' in a header or cell ('max |pole|',
    a verdict's '|z|') is escaped, not a cell's end."""
    lines = ["| " + " | ".join(c.replace("|", "\\|") for c in r) + " |" for r in [headers, *rows]]
    return "\n".join([lines[0], "|" + "---|" * len(headers), *lines[1:]])
