"""The identification figures, in one style: an experiment's input and output (the report's
figures 3, 11), measured against simulated speed (6, 7), the ETFE with the models' Bode plots (4),
the pole-zero map (5, 12) and the residual tests. matplotlib is imported inside the functions,
and figures have their own canvases (no pyplot state)."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from cartctl.data.outputs import writing
from cartctl.errors import InputError
from cartctl.identification.etfe import Etfe, model_response
from cartctl.measures.metrics import fit_percent
from cartctl.model import ArxModel

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from matplotlib.typing import RcKeyType

    from cartctl.data.trace import Trace
    from cartctl.identification.diagnostics import BodeBand, ResidualTest


DPI = 110  # resolution of the PNG files (dots per inch); 10 × 6.5 in figures are 1100 × 715 px

_STYLE: dict[RcKeyType, Any] = {
    "font.size": 10,
    "axes.titlesize": 11,
    "axes.labelsize": 10,
    "legend.fontsize": 9,
    "figure.titlesize": 13,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "lines.linewidth": 1.4,
}
_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


@contextmanager
def figure(width_in: float, height_in: float, path: Path, title: str) -> Iterator[Figure]:
    """A constrained-layout figure drawn under the report's style (no pyplot, nothing to close),
    titled and saved to ``path`` at the end of the block."""
    import matplotlib as mpl
    from matplotlib.figure import Figure

    with mpl.rc_context(_STYLE):
        fig = Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
        yield fig
        fig.suptitle(title)
        with writing(path):  # a full disk: a fault naming the figure
            fig.savefig(path, dpi=DPI)


def color(i: int) -> str:
    return _COLORS[i % len(_COLORS)]


def plot_io(
    trace: Trace,
    motors: Sequence[str],
    path: Path,
    *,
    title: str,
    zoom_s: tuple[float, float] | None = None,
) -> Path:
    """Input and output of an experiment per motor (report, figures 3 and 11); returns ``path``.
    Per motor voltage (V) above speed (rad/s), and the speed again over ``zoom_s`` (s)."""
    if not motors:
        raise InputError("plot_io needs at least one motor, e.g. ('a', 'b')")
    if zoom_s is not None and not zoom_s[0] < zoom_s[1]:
        raise InputError(f"zoom window must be (start_s, end_s) with start < end, got {zoom_s}")
    t = trace.time_s
    rows = 3 if zoom_s is not None else 2
    with figure(max(9.0, 5.5 * len(motors) + 0.5), 2.4 * rows + 0.8, path, title) as fig:
        grid = fig.add_gridspec(rows, len(motors), height_ratios=[1.0, 1.4, 1.4][:rows])
        first = None
        for j, motor in enumerate(motors):
            speed = trace.speed(motor)
            ax_v = fig.add_subplot(grid[0, j], sharex=first)
            first = first or ax_v
            ax_w = fig.add_subplot(grid[1, j], sharex=first, ylabel="speed (rad/s)")
            ax_v.plot(t, trace.voltage(motor), drawstyle="steps-post", color="tab:blue")
            ax_v.set(title=f"Motor {motor.upper()}", ylabel="voltage (V)")
            ax_w.plot(t, speed, color="tab:red", linewidth=1.0)
            ax_v.tick_params(labelbottom=False)
            if zoom_s is None:
                ax_w.set_xlabel("time (s)")
                continue
            ax_w.axvspan(*zoom_s, color="0.85", zorder=0)
            ax_z = fig.add_subplot(grid[2, j], ylabel="speed (rad/s)", xlabel="time (s)")
            inside = (t >= zoom_s[0]) & (t <= zoom_s[1])
            ax_z.plot(t[inside], speed[inside], color="tab:red", linewidth=1.2)
            ax_z.set_xlim(*zoom_s)
            ax_z.set_title(f"zoom {zoom_s[0]:g}–{zoom_s[1]:g} s", fontsize=10)
        if len(t) and first is not None:
            first.set_xlim(t[0], t[-1])
    return Path(path)


def plot_step_validation(
    time_s: ArrayLike,
    voltage: ArrayLike,
    measured: ArrayLike,
    simulated: Mapping[str, ArrayLike],
    path: Path,
    *,
    title: str,
) -> Path:
    """Measured against simulated speed (rad/s, label → array, the legend with each fit in %)
    above |error|, under the voltage (V) (report, figures 6, 7); returns ``path``."""
    t = np.asarray(time_s, dtype=float)
    series = {"voltage": np.asarray(voltage, dtype=float), "measured": np.asarray(measured, float)}
    series |= {f"simulated[{k!r}]": np.asarray(v, dtype=float) for k, v in simulated.items()}
    for name, values in series.items():
        if values.ndim != 1 or values.shape != t.shape or t.ndim != 1:
            raise InputError(
                f"{name} must be 1-D with one value per time step ({t.shape}), got {values.shape}"
            )
    y = series["measured"]
    with figure(10.0, 7.5, path, title) as fig:
        ax_u, ax_y, ax_e = fig.subplots(3, 1, sharex=True, height_ratios=[1.0, 2.6, 1.6])
        ax_u.plot(t, series["voltage"], drawstyle="steps-post", color="tab:blue")
        ax_u.set(ylabel="voltage (V)")
        ax_y.plot(t, y, color="black", linewidth=2.0, label="measured")
        for i, (label, given) in enumerate(simulated.items()):
            sim = np.asarray(given, dtype=float)
            fit = fit_percent(y, sim)
            ax_y.plot(t, sim, color=color(i), label=f"{label} (fit {fit:.1f} %)")
            ax_e.plot(t, np.abs(y - sim), color=color(i))
        ax_y.set(ylabel="speed (rad/s)")
        ax_e.set(ylabel="|error| (rad/s)", xlabel="time (s)")
        if t.size:
            ax_e.set_xlim(t[0], t[-1])
        fig.legend(*ax_y.get_legend_handles_labels(), loc="outside lower center", ncols=3)
    return Path(path)


def plot_etfe(
    etfe: Etfe,
    models: Mapping[str, ArxModel],
    path: Path,
    *,
    title: str,
    band: BodeBand | None = None,
) -> Path:
    """ETFE as dots and each model's Bode plot as a line (report, figure 4); returns ``path``.

    Magnitude (dB re 1 rad/s per V) above, phase (deg, each ETFE point moved by whole turns to the
    first model's branch) below, up to Nyquist; ``band`` shades the first model's 1σ, 2σ bands.
    """
    from matplotlib.ticker import FuncFormatter, LogLocator, MultipleLocator, NullFormatter

    positive = etfe.freq_hz > 0.0
    if not np.any(positive):
        raise InputError("the ETFE has no frequency above 0 Hz to draw on a logarithmic axis")
    f_e = etfe.freq_hz[positive]
    h_e = etfe.response[positive]
    nyquist_hz = 0.5 / etfe.period_s
    f_lo = float(f_e[0]) / 1.5
    f_grid = np.geomspace(f_lo, nyquist_hz, 800)
    curves = []
    for label, model in models.items():
        h = model_response(model, f_grid)
        curves.append((label, 20.0 * np.log10(np.abs(h)), np.degrees(np.unwrap(np.angle(h)))))
    phase_e = np.degrees(np.angle(h_e))
    if curves:
        ref = np.interp(np.log(f_e), np.log(f_grid), curves[0][2])
        phase_e += 360.0 * np.round((ref - phase_e) / 360.0)
    else:
        phase_e = np.degrees(np.unwrap(np.angle(h_e)))
    n = etfe.n_segments
    kind = f"{n} period{'s' if n != 1 else ''} averaged" if etfe.periodic else "whole record"
    if not etfe.periodic and n > 1:
        kind = f"{n} Hann segments"
    with figure(10.0, 7.0, path, title) as fig:
        ax_m, ax_p = fig.subplots(2, 1, sharex=True)
        style = {"linestyle": "none", "marker": "o", "markersize": 3.5, "color": "0.15"}
        ax_m.plot(f_e, 20.0 * np.log10(np.abs(h_e)), label=f"ETFE ({kind})", **style)
        ax_p.plot(f_e, phase_e, **style)
        if band is not None and curves:
            _draw_band(ax_m, ax_p, band, f_lo, curves[0][0])
        for i, (label, mag_db, phase_deg) in enumerate(curves):
            ax_m.plot(f_grid, mag_db, color=color(i), label=label, linewidth=1.8)
            ax_p.plot(f_grid, phase_deg, color=color(i), linewidth=1.8)
        ax_m.set(xscale="log", xlim=(f_lo, nyquist_hz), ylabel="magnitude (dB re 1 rad/s/V)")
        ax_p.set(ylabel="phase (deg)")
        ax_p.set_xlabel(f"frequency (Hz), up to the Nyquist frequency {nyquist_hz:g} Hz")
        ax_p.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax_p.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos: f"{x:g}"))
        ax_p.xaxis.set_minor_formatter(NullFormatter())
        span = float(np.ptp(np.concatenate([phase_e, *(c[2] for c in curves)])))
        ax_p.yaxis.set_major_locator(MultipleLocator(90.0 if span <= 540.0 else 180.0))
        for ax in (ax_m, ax_p):
            ax.grid(True, which="minor", alpha=0.12)
        ax_m.legend(loc="lower left")
    return Path(path)


def _draw_band(ax_m: Any, ax_p: Any, band: BodeBand, f_lo: float, label: str) -> None:
    """Shade the 2σ (light) and 1σ (darker) bands of the first model on both panels."""
    keep = band.freq_hz >= f_lo
    f = band.freq_hz[keep]
    for row, alpha, name in ((1, 0.15, "2σ"), (0, 0.3, "1σ")):
        style = {"lw": 0, "color": color(0), "alpha": alpha}
        ax_m.fill_between(
            f, *band.mag_db_bands[row][:, keep], label=f"{label}: {name} band", **style
        )
        ax_p.fill_between(f, *band.phase_deg_bands[row][:, keep], **style)


def plot_pzmap(models: Mapping[str, ArxModel], path: Path, *, title: str) -> Path:
    """Pole-zero map of one or more models (report, figures 5 and 12); returns ``path``.

    Poles ×, zeros ○, delay poles at z = 0 as one square with their count, the other poles
    labelled with their frequency (Hz); the whole circle beside a zoom on the roots inside it.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Rectangle

    if not models:
        raise InputError("plot_pzmap needs at least one model")
    roots = {label: (m.poles(), m.zeros()) for label, m in models.items()}
    values = np.array([r.value for pz in roots.values() for r in (*pz[0], *pz[1])] + [0j])
    reach = max(1.15, 1.1 * float(np.max(np.abs(values))))
    zoom = _zoom_window(values[np.abs(values) <= 1.05])
    if zoom[1] - zoom[0] >= 1.6:  # the roots inside fill the circle: show all of it
        zoom = (-1.15, 1.15, -1.15, 1.15)
    zoomed = zoom[1] - zoom[0] < 1.6 or reach > 1.2
    with figure(11.0, 5.8 if zoomed else 6.5, path, title) as fig:
        panels = list(fig.subplots(1, 2, width_ratios=[1.0, 1.5])) if zoomed else [fig.subplots()]
        ax_full, ax_zoom = panels[0], panels[-1]
        for ax in panels:
            ax.add_patch(Circle((0, 0), 1.0, fill=False, color="0.4", linestyle="--", lw=1.0))
            ax.axhline(0.0, color="0.5", lw=0.8)
            ax.axvline(0.0, color="0.5", lw=0.8)
            ax.set(aspect="equal", adjustable="box", xlabel="real part", ylabel="imaginary part")
        full = "unit circle" if reach < 1.2 else "all roots (unit circle dashed)"
        ax_full.set(xlim=(-reach, reach), ylim=(-reach, reach), title=full)
        if zoomed:
            what = "unit circle" if zoom[1] - zoom[0] > 2.0 else "zoom"
            ax_zoom.set(xlim=zoom[:2], ylim=zoom[2:], title=what)
            box = Rectangle((zoom[0], zoom[2]), zoom[1] - zoom[0], zoom[3] - zoom[2], fill=False)
            ax_full.add_patch(box)
        delays: dict[str, int] = {}
        labels: list[tuple[complex, str, str]] = []
        handles = []
        for i, (label, (poles, zeros)) in enumerate(roots.items()):
            tint = color(i)
            p = np.array([r.value for r in poles if r.kind != "delay"], dtype=complex)
            z = np.array([r.value for r in zeros], dtype=complex)
            delays[label] = sum(r.kind == "delay" for r in poles)
            for ax in panels:
                ax.plot(p.real, p.imag, "x", color=tint, markersize=10, mew=2.2)
                ax.plot(z.real, z.imag, "o", mfc="none", color=tint, markersize=9, mew=1.8)
            handles.append(Line2D([], [], color=tint, lw=5, label=label))
            labels += [
                (r.value, f"{r.freq_hz:.1f} Hz", tint)
                for r in poles
                if r.kind != "delay" and r.value.imag >= 0.0 and r.freq_hz is not None
            ]
        if any(delays.values()):
            for ax in panels:
                ax.plot(0.0, 0.0, "s", color="black", markersize=7, zorder=5)
            counts = set(delays.values())
            each = ", ".join(f"{k}: {n}" for k, n in delays.items())
            text = f"{counts.pop()} per model" if len(counts) == 1 else each
            ax_zoom.annotate(
                f"delay poles at z = 0\n({text})",
                (0.0, 0.0),
                xytext=(14, -52),
                textcoords="offset points",
                ha="left",
                va="top",
                fontsize=8.5,
                arrowprops={"arrowstyle": "-", "color": "0.3", "lw": 0.8},
            )
        _label_poles(ax_zoom, labels, zoom[1] - zoom[0] if zoomed else 2.0 * reach)
        handles += [
            Line2D([], [], ls="none", marker="x", color="black", markersize=9, mew=2, label="pole"),
            Line2D([], [], ls="none", marker="o", mfc="none", color="black", label="zero"),
            Line2D([], [], ls="none", marker="s", color="black", label="delay pole (z = 0)"),
        ]
        fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4))
    return Path(path)


def _zoom_window(values: np.ndarray) -> tuple[float, float, float, float]:
    """(x_lo, x_hi, y_lo, y_hi) around the roots and the origin, padded, about 5:3 wide."""
    re = np.append(values.real, 0.0)
    im_max = float(np.max(np.abs(values.imag))) if values.size else 0.0
    x_lo, x_hi = float(re.min()), float(re.max())
    width = max(x_hi - x_lo, 2.0 * im_max, 0.2)
    pad = 0.12 * width
    half_h = max(im_max + pad, 0.3 * (x_hi - x_lo + 2 * pad))
    return x_lo - pad, x_hi + pad, -half_h, half_h


def _label_poles(ax: Any, labels: list[tuple[complex, str, str]], view_width: float) -> None:
    """Write each pole's frequency beside it, alternating above and below to avoid overlaps."""
    offsets = [(0, 14), (0, -22), (0, 28), (0, -36), (0, 42), (0, -50)]
    min_dx = 0.14 * view_width
    last_x = [-math.inf] * len(offsets)
    for value, text, tint in sorted(labels, key=lambda item: item[0].real):
        level = next(
            (k for k in range(len(offsets)) if value.real - last_x[k] >= min_dx),
            int(np.argmin(last_x)),
        )
        last_x[level] = value.real
        ax.annotate(
            text,
            (value.real, value.imag),
            xytext=offsets[level],
            textcoords="offset points",
            ha="center",
            va="center",
            color=tint,
            fontsize=9,
            fontweight="bold",
            arrowprops={"arrowstyle": "-", "color": tint, "lw": 0.7, "shrinkA": 0, "shrinkB": 5},
        )


def plot_residuals(test: ResidualTest, path: Path, *, title: str) -> Path:
    """Autocorrelation above, cross-correlation with the input below, 99 % bounds shaded;
    returns ``path``."""
    if test.negligible:
        title += "\nresiduals at rounding level (RMS below 1e-6 of the output's): no test"
    panels = {
        "auto": ("white", "autocorrelation of the residuals r_ε(τ)"),
        "cross": ("independent", "cross-correlation with the input r_εu(τ)"),
    }
    with figure(9.0, 6.2, path, title) as fig:
        ax_a, ax_c = axes = fig.subplots(2, 1)
        for ax, (kind, (word, what)) in zip(axes, panels.items(), strict=True):
            lags, r, outside = (getattr(test, kind + k) for k in ("_lags", "", "_outside"))
            bound = test.bound_99 if kind == "auto" else test.cross_bound_99
            ax.axhspan(-bound, bound, color="tab:blue", alpha=0.15, lw=0, label="99 % bound")
            ax.axhline(0.0, color="0.3", lw=0.8)
            inside = np.abs(r) <= bound
            ax.vlines(lags, 0.0, r, color="0.25", lw=1.2)
            ax.plot(lags[inside], r[inside], "o", color="0.25", markersize=4)
            ax.plot(lags[~inside], r[~inside], "o", color="tab:red", markersize=5)
            reach = max(1.6 * bound, 1.15 * float(np.max(np.abs(r))))
            ax.set(ylim=(-reach, reach), xlim=(lags[0] - 0.8, lags[-1] + 0.8))
            ax.set_ylabel("correlation (–)")
            verdict = word if getattr(test, word) else f"not {word}"
            what += f": {outside} of {lags.size} lags outside ±{bound:.3f} ({verdict})"
            ax.set_title(what, fontsize=10)
        ax_a.set_xlabel("lag τ (ticks)")
        ax_c.set_xlabel("lag τ (ticks); τ > 0: input before the residual")
        ax_a.legend(loc="upper right")
    return Path(path)
