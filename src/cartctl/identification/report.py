"""The time-domain figures and the markdown summary of ``cartctl identify --report``: the
experiment's input and output (the report's figures 3, 11) and the step validation (figures 6, 7);
the frequency-domain ones live in :mod:`~cartctl.identification.plots_freq`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cartctl.data.trace import Trace
from cartctl.errors import InputError
from cartctl.identification.plots_freq import color, figure, plot_etfe, plot_pzmap, save
from cartctl.measures.metrics import fit_percent

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
    """Input and output of an experiment per motor (report, figures 3 and 11); returns ``path``.

    One column per motor: voltage (V) above, speed (rad/s) below; with ``zoom_s`` (start, end in
    s) a third row repeats the speed over that window, shaded above.
    """
    if not motors:
        raise InputError("plot_io needs at least one motor, e.g. ('a', 'b')")
    if zoom_s is not None and not zoom_s[0] < zoom_s[1]:
        raise InputError(f"zoom window must be (start_s, end_s) with start < end, got {zoom_s}")
    t = trace.time_s
    rows = 3 if zoom_s is not None else 2
    with figure(max(9.0, 5.5 * len(motors) + 0.5), 2.4 * rows + 0.8) as fig:
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
        return save(fig, path)


def plot_step_validation(
    time_s: ArrayLike,
    voltage: ArrayLike,
    measured: ArrayLike,
    simulated: Mapping[str, ArrayLike],
    path: Path,
    *,
    title: str,
) -> Path:
    """Measured against simulated speed with |error| beneath (report, figures 6, 7); returns
    ``path``.

    Three panels on one time axis (s): voltage (V); the measured and each ``simulated`` speed
    (rad/s, label → array, the legend with each simulation fit in %); |measured − simulated|.
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
    with figure(10.0, 7.5) as fig:
        ax_u, ax_y, ax_e = fig.subplots(3, 1, sharex=True, height_ratios=[1.0, 2.6, 1.6])
        ax_u.plot(t, series["voltage"], drawstyle="steps-post", color="tab:blue")
        ax_u.set_ylabel("voltage (V)")
        ax_y.plot(t, y, color="black", linewidth=2.0, label="measured")
        for i, (label, given) in enumerate(simulated.items()):
            sim = np.asarray(given, dtype=float)
            fit = fit_percent(y, sim)
            ax_y.plot(t, sim, color=color(i), label=f"{label} (fit {fit:.1f} %)")
            ax_e.plot(t, np.abs(y - sim), color=color(i))
        ax_y.set_ylabel("speed (rad/s)")
        ax_e.set_ylabel("|error| (rad/s)")
        ax_e.set_xlabel("time (s)")
        if t.size:
            ax_e.set_xlim(t[0], t[-1])
        fig.legend(*ax_y.get_legend_handles_labels(), loc="outside lower center", ncols=3)
        fig.suptitle(title)
        return save(fig, path)


@dataclass(frozen=True)
class ReportSection:
    """One ``## heading`` of ``summary.md``: markdown text, figures (relative to the summary's
    folder; absolute paths are made relative) and an optional table (rows of column → value,
    columns in order of first appearance, floats to 4 significant digits)."""

    heading: str
    text: str = ""
    images: Sequence[str | Path] = ()
    table: Sequence[Mapping[str, Any]] | None = None


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
    """Write ``out_dir/summary.md`` (the title, then each section's text, figures and table)
    and return its path."""
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
