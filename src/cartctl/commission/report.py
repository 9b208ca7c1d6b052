"""Commissioning's ``summary.md`` and its figures: one section per stage, written as stages end.

:class:`Report` keeps the sections so far and rewrites ``summary.md`` after each stage, so a run
stopped anywhere (a failed stage, Ctrl-C) leaves a readable summary of what was done. The figures
are PNGs beside it (matplotlib, no display needed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray


def fmt(value: float | None, digits: int = 2, scale: float = 1.0, unit: str = "") -> str:
    """A figure for a table: '—' for None, '∞' for infinity."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if math.isinf(value):
        return "∞"
    return f"{value * scale:.{digits}f}{unit}"


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


@dataclass
class Report:
    """The summary's sections, rewritten to ``path`` on every :meth:`add`.

    Attributes
    ----------
    path : Path
        ``summary.md``.
    title : str
    sections : list of (str, str)
        (heading, Markdown body) in stage order.
    """

    path: Path
    title: str
    sections: list[tuple[str, str]] = field(default_factory=list)

    def add(self, heading: str, body: str) -> None:
        """Add (or replace) a section and rewrite the file."""
        self.sections = [(h, b) for h, b in self.sections if h != heading]
        self.sections.append((heading, body))
        self.write()

    def write(self) -> None:
        """Write ``summary.md`` (via a temporary file: the old one stays whole until then)."""
        text = f"# {self.title}\n\n" + "\n\n".join(f"## {h}\n\n{b.strip()}"
                                                  for h, b in self.sections) + "\n"  # fmt: skip
        tmp = self.path.with_suffix(".md.tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(self.path)


def plot_lines(path: Path, title: str,
               panels: Sequence[tuple[str, Mapping[str, tuple[NDArray[np.float64], NDArray[np.float64]]]]],
               xlabel: str = "time (s)") -> Path:  # fmt: skip
    """Stacked panels of labelled lines: ``panels`` = [(y label, {legend: (x, y)}), ...]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(8, 2.6 * len(panels)),
                             squeeze=False)  # fmt: skip
    for ax, (ylabel, lines) in zip(axes[:, 0], panels, strict=True):
        for label, (x, y) in lines.items():
            ax.plot(x, y, label=label, lw=1.2)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel(xlabel)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def checks_body(loop_delay_ticks: int | None, checks: Mapping[str, Any], plant: str,
                amplitude: Any | None) -> str:  # fmt: skip
    """The checks section: the plant, the loop delay, each motor's figures, the amplitude rule."""
    rows = [[m, c.direction, fmt(c.pulse_turn_rad, 3), fmt(c.other_turn_rad, 3),
             fmt(c.breakaway_v, 2), fmt(c.gain_rad_s_v, 2)] for m, c in checks.items()]  # fmt: skip
    body = (f"Plant: {plant}. Loop delay: {loop_delay_ticks} tick(s) (measurement to applied "
            "voltage).\n\n"
            + table(["motor", "direction", "pulse turn (rad)", "other wheel (rad)",
                     "breakaway (V)", "gain (rad/s/V)"], rows))  # fmt: skip
    if amplitude is not None:
        body += (f"\n\nExcitation amplitude: **{amplitude.voltage_v:g} V**. Rule: "
                 f"{amplitude.rule}.")  # fmt: skip
    return body + "\n\nFiles: checks.csv, checks.rrd, checks.png."


def model_body(result: Any, verdicts: Mapping[str, Any], model_name: str) -> str:
    """The identification section: θ, nk, DC gain, validation figures, verdicts."""
    rows = []
    for m, r in result.motors.items():
        v = verdicts[m]
        model = r.chosen.model
        rows.append([m, ", ".join(f"{x:.4g}" for x in model.theta), str(model.nk),
                     fmt(model.dc_gain(), 3), fmt(v.fit_percent, 1), fmt(v.pole_radius, 3),
                     f"{v.cross_outside}/{v.cross_lags} ({v.cross_ratio:.1f}×)", "yes" if v.white else "no",
                     "pass" if not v.problems else "FAIL: " + "; ".join(v.problems)])  # fmt: skip
    return (table(["motor", "θ = [a1, a2, b0 …]", "nk", "DC gain (rad/s/V)",
                   "validation fit (%)", "max |pole|", "cross-corr. lags outside (max/bound)",
                   "white", "verdict"], rows)
            + "".join(f"\n\n{note}." for note in result.notes)
            + f"\n\nFiles: {model_name}, identification.rrd, identification.png.")  # fmt: skip
