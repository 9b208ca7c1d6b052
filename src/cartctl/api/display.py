"""How the Python API's results show themselves: a few lines for ``print()``, a small table in
Jupyter, and the figure of a simulated run.

A :class:`Summary` is a title, one table row per motor and a line of hints; ``__repr__`` prints
it as text and ``_repr_html_`` as an HTML table, so both show the same numbers. matplotlib is
imported only when a figure is drawn.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.measures.numfmt import MISSING, render_table

__all__ = ["Summary", "number", "numbers", "plot_run"]


def number(value: float | None, digits: int = 4) -> str:
    """``value`` with ``digits`` significant figures; a dash for None or NaN."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return MISSING
    text = f"{float(value):.{digits}g}"
    return "0" if text == "-0" else text


def numbers(values: Iterable[float], digits: int = 4) -> str:
    """A short list ``[-0.9157, 0.2044, …]`` of ``values`` with ``digits`` significant figures."""
    return "[" + ", ".join(number(v, digits) for v in values) + "]"


@dataclass(frozen=True)
class Summary:
    """A result in a few lines: a title, a table (one row per motor) and a line of hints.

    Attributes
    ----------
    title : str
    headers : tuple of str
        The table's column headers, units in them (``"settling (s)"``).
    rows : tuple of tuple of str
        The cells, already formatted.
    hint : str
        What else the object offers (``".plot(), .to_dataframe()"``); empty for none.
    """

    title: str
    headers: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    hint: str = ""

    def text(self) -> str:
        """The summary for ``print()`` and ``repr()``."""
        lines = [self.title, *render_table(self.headers, self.rows, indent="  ")]
        if self.hint:
            lines.append("  " + self.hint)
        return "\n".join(lines)

    def html(self) -> str:
        """The summary for Jupyter: the title, an HTML table and the hints."""
        esc = html.escape
        head = "".join(f"<th>{esc(h)}</th>" for h in self.headers)
        body = "".join(
            "<tr>" + "".join(f"<td>{esc(c)}</td>" for c in row) + "</tr>" for row in self.rows
        )
        hint = f"<br><small>{esc(self.hint)}</small>" if self.hint else ""
        return (
            f"<div><strong>{esc(self.title)}</strong>"
            f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>{hint}</div>"
        )


def _drawn(columns: Mapping[str, NDArray[np.float64]], name: str) -> NDArray[np.float64]:
    """A column without the stop row (the zero-volt command a run ends with)."""
    values = np.asarray(columns[name], dtype=float)
    return values[:-1] if values.size > 1 else values


def plot_run(
    columns: Mapping[str, NDArray[np.float64]],
    motors: Sequence[str],
    title: str,
    axes: Any = None,
) -> Any:
    """Speed with its reference over voltage, per motor, of a run's trace; returns the figure.

    The stop row (the last row of every run's trace: the zero-volt command sent when the run
    ended) is not drawn, so the voltage does not seem to drop to 0 V at the end.

    Parameters
    ----------
    columns : mapping of str to ndarray, shape (n,)
        The trace: ``time_s`` (s), ``reference_m``, ``speed_m``, ``true_speed_m`` (rad/s, optional),
        ``estimate_m`` (rad/s, optional) and ``voltage_m`` (V) for each motor m.
    motors : sequence of {'a', 'b'}
        One column of axes per motor.
    title : str
        The figure's title (what ran, on which plant).
    axes : sequence of two matplotlib Axes, optional
        Where to draw one motor (speed axes, voltage axes); a new figure when None.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if axes is None:
        import matplotlib.pyplot as plt

        fig, grid = plt.subplots(2, len(motors), sharex=True, squeeze=False,
                                 figsize=(4 + 4.5 * len(motors), 6), layout="constrained")  # fmt: skip
        pairs = [(grid[0][i], grid[1][i]) for i in range(len(motors))]
    else:
        if len(motors) != 1 or len(axes) != 2:
            raise ValueError("axes: give (speed_axes, voltage_axes) for one motor")
        pairs = [tuple(axes)]
        fig = pairs[0][0].figure
    time_s = _drawn(columns, "time_s")
    for motor, (top, bottom) in zip(motors, pairs, strict=True):
        top.plot(time_s, _drawn(columns, f"reference_{motor}"), "k--", label="reference")
        top.plot(time_s, _drawn(columns, f"speed_{motor}"), label="measured speed")
        for name, label in (("true_speed", "true speed"), ("estimate", "estimate")):
            values = columns.get(f"{name}_{motor}")
            if (
                values is not None
                and np.isfinite(values).any()
                and not np.array_equal(values, columns[f"speed_{motor}"])
            ):
                top.plot(time_s, _drawn(columns, f"{name}_{motor}"), label=label, alpha=0.8)
        top.set_title(f"motor {motor}")
        top.set_ylabel("speed (rad/s)")
        top.legend(loc="lower right", fontsize="small")
        top.grid(True, alpha=0.3)
        bottom.step(time_s, _drawn(columns, f"voltage_{motor}"), where="post", color="C3",
                    label="commanded voltage")  # fmt: skip
        bottom.set_ylabel("voltage (V)")
        bottom.set_xlabel("time (s)")
        bottom.legend(loc="lower right", fontsize="small")
        bottom.grid(True, alpha=0.3)
    fig.suptitle(title)
    return fig
