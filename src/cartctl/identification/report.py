"""Figures and a markdown summary of an identification (``cartctl identify --report``).

Identification stage, at its edge: the numeric work is done elsewhere (:mod:`~cartctl.identification.etfe`,
the fits, validation); this module draws what a person looks at, after the report's figures:
the experiment's input and output (figures 3, 11) and the step validation (figures 6, 7) here,
the ETFE with the models' Bode plots (figure 4) and the pole-zero map (figures 5, 12) in
:mod:`~cartctl.identification.plots_freq`; and writes ``summary.md`` embedding them.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from cartctl.data.trace import Trace
from cartctl.errors import InputError
from cartctl.identification.figure_base import color as _color
from cartctl.identification.figure_base import figure as _figure
from cartctl.identification.figure_base import save as _save
from cartctl.identification.plots_freq import plot_etfe, plot_pzmap
from cartctl.measures.metrics import fit_percent

if TYPE_CHECKING:
    pass

__all__ = [
    "ReportSection",
    "plot_etfe",
    "plot_io",
    "plot_pzmap",
    "plot_step_validation",
    "write_summary",
]


def plot_io(
    trace: Trace,
    motors: Sequence[str],
    path: Path,
    *,
    title: str,
    zoom_s: tuple[float, float] | None = None,
) -> Path:
    """Input and output of an experiment per motor (report, figures 3 and 11).

    One column per motor: commanded voltage (V) above, measured speed (rad/s) below, against
    time (s). With ``zoom_s`` a third row repeats the speed over that window (shaded above), as
    the report zooms in on one cycle.

    Parameters
    ----------
    trace : Trace
        The experiment.
    motors : sequence of str
        Motors to show, e.g. ``("a", "b")``.
    path : Path
        PNG file to write (folders are created).
    title : str
        Figure title.
    zoom_s : (float, float), optional
        Start and end of the zoom window (s).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        No motors, an unknown motor, or an empty or reversed zoom window.
    """
    if not motors:
        raise InputError("plot_io needs at least one motor, e.g. ('a', 'b')")
    if zoom_s is not None and not zoom_s[0] < zoom_s[1]:
        raise InputError(f"zoom window must be (start_s, end_s) with start < end, got {zoom_s}")
    t = trace.time_s
    rows = 3 if zoom_s is not None else 2
    with _figure(max(9.0, 5.5 * len(motors) + 0.5), 2.4 * rows + 0.8) as fig:
        grid = fig.add_gridspec(rows, len(motors), height_ratios=[1.0, 1.4, 1.4][:rows])
        first = None
        for j, motor in enumerate(motors):
            voltage, speed = trace.voltage(motor), trace.speed(motor)
            ax_v = fig.add_subplot(grid[0, j], sharex=first)
            first = first or ax_v
            ax_w = fig.add_subplot(grid[1, j], sharex=first)
            ax_v.plot(t, voltage, drawstyle="steps-post", color="tab:blue")
            ax_v.set_title(f"Motor {motor.upper()}")
            ax_v.set_ylabel("voltage (V)")
            ax_w.plot(t, speed, color="tab:red", linewidth=1.0)
            ax_w.set_ylabel("speed (rad/s)")
            ax_v.tick_params(labelbottom=False)
            if zoom_s is None:
                ax_w.set_xlabel("time (s)")
                continue
            ax_w.axvspan(*zoom_s, color="0.85", zorder=0)
            ax_z = fig.add_subplot(grid[2, j])
            inside = (t >= zoom_s[0]) & (t <= zoom_s[1])
            ax_z.plot(t[inside], speed[inside], color="tab:red", linewidth=1.2)
            ax_z.set_xlim(*zoom_s)
            ax_z.set_ylabel("speed (rad/s)")
            ax_z.set_xlabel("time (s)")
            ax_z.set_title(f"zoom {zoom_s[0]:g}–{zoom_s[1]:g} s", fontsize=10)
        if len(t) and first is not None:
            first.set_xlim(t[0], t[-1])
        fig.suptitle(title)
        return _save(fig, path)


def plot_step_validation(
    time_s: ArrayLike,
    voltage: ArrayLike,
    measured: ArrayLike,
    simulated: Mapping[str, ArrayLike],
    path: Path,
    *,
    title: str,
) -> Path:
    """Measured against simulated speed, with the absolute error beneath (report, figures 6, 7).

    Three panels sharing the time axis: the voltage applied (V), the measured speed and each
    model's simulated speed (rad/s; the legend gives each model's simulation fit in percent,
    see :func:`cartctl.measures.metrics.fit_percent`), and |measured − simulated| (rad/s).

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Time of each tick (s).
    voltage : array_like, shape (n,)
        Applied voltage (V).
    measured : array_like, shape (n,)
        Measured speed (rad/s).
    simulated : mapping of str to array_like, each shape (n,)
        Label → simulated speed (rad/s).
    path : Path
        PNG file to write.
    title : str
        Figure title.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        Sequences of different lengths or not 1-D.
    """
    t = np.asarray(time_s, dtype=float)
    series = {"voltage": np.asarray(voltage, dtype=float), "measured": np.asarray(measured, float)}
    series |= {f"simulated[{k!r}]": np.asarray(v, dtype=float) for k, v in simulated.items()}
    for name, values in series.items():
        if values.ndim != 1 or values.shape != t.shape or t.ndim != 1:
            raise InputError(
                f"{name} must be 1-D with one value per time step ({t.shape}), got {values.shape}"
            )
    y = series["measured"]
    with _figure(10.0, 7.5) as fig:
        ax_u, ax_y, ax_e = fig.subplots(3, 1, sharex=True, height_ratios=[1.0, 2.6, 1.6])
        ax_u.plot(t, series["voltage"], drawstyle="steps-post", color="tab:blue")
        ax_u.set_ylabel("voltage (V)")
        ax_y.plot(t, y, color="black", linewidth=2.0, label="measured")
        for i, (label, given) in enumerate(simulated.items()):
            sim = np.asarray(given, dtype=float)
            fit = fit_percent(y, sim)
            ax_y.plot(t, sim, color=_color(i), label=f"{label} (fit {fit:.1f} %)")
            ax_e.plot(t, np.abs(y - sim), color=_color(i))
        ax_y.set_ylabel("speed (rad/s)")
        ax_e.set_ylabel("|error| (rad/s)")
        ax_e.set_xlabel("time (s)")
        if t.size:
            ax_e.set_xlim(t[0], t[-1])
        fig.legend(*ax_y.get_legend_handles_labels(), loc="outside lower center", ncols=3)
        fig.suptitle(title)
        return _save(fig, path)


@dataclass(frozen=True)
class ReportSection:
    """One section of ``summary.md``.

    Attributes
    ----------
    heading : str
        Section heading (rendered as ``## heading``).
    text : str
        Markdown paragraph(s) under the heading.
    images : sequence of str or Path
        Figures to embed, relative to the summary's folder (absolute paths are made relative).
    table : sequence of mapping, optional
        Rows of a table, column name → value; columns in order of first appearance. Floats are
        written with 4 significant digits.
    """

    heading: str
    text: str = ""
    images: Sequence[str | Path] = ()
    table: Sequence[Mapping[str, Any]] | None = field(default=None)


def _cell(value: Any) -> str:
    if value is None:
        return ""
    text = f"{float(value):.4g}" if isinstance(value, float | np.floating) else str(value)
    return text.replace("|", "\\|").replace("\n", " ")


def _table(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    columns: list[str] = []
    for row in rows:
        columns += [str(name) for name in row if str(name) not in columns]
    lines = ["| " + " | ".join(_cell(c) for c in columns) + " |"]
    lines.append("|" + "|".join(" --- " for _ in columns) + "|")
    for row in rows:
        cells = {str(k): v for k, v in row.items()}
        lines.append("| " + " | ".join(_cell(cells.get(c)) for c in columns) + " |")
    return lines


def write_summary(out_dir: Path, *, title: str, sections: Sequence[ReportSection]) -> Path:
    """Write ``out_dir/summary.md``: the title, then each section's text, figures and table.

    Parameters
    ----------
    out_dir : Path
        Folder of the report (created if missing); image paths are relative to it.
    title : str
        Document title (``# title``).
    sections : sequence of ReportSection
        In order.

    Returns
    -------
    Path
        The summary file written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = [f"# {title}", ""]
    for section in sections:
        lines += [f"## {section.heading}", ""]
        if section.text.strip():
            lines += [section.text.strip(), ""]
        for image in section.images:
            image = Path(image)
            rel = Path(os.path.relpath(image, out_dir)) if image.is_absolute() else image
            lines += [f"![{rel.stem}]({rel.as_posix()})", ""]
        if section.table:
            lines += [*_table(section.table), ""]
    path = out_dir / "summary.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path
