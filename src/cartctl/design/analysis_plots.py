"""``cartctl design --report DIR``: the loop analysis figure per motor (``analysis_a.png`` …).

Four panels: |S| and |T| (dB) against frequency up to Nyquist with the peaks Ms and Mt marked; the
Nyquist curve of L with the point −1 and the circle of radius 1/Ms around it that the curve
touches; the speed deviation after a load-disturbance step with its peak and recovery; and the
controller's voltage answering it. matplotlib's Agg canvas, every label inside its axes.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cartctl.design.loop_report import MotorAnalysis
from cartctl.design.numbers import db, sig

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _db(value: float) -> str:
    return db(20.0 * float(np.log10(value)))


def plot_analysis(path: Path, motor: str, method: str, analysis: MotorAnalysis) -> Path:
    """Write one motor's analysis figure (see the module docstring) as PNG; returns ``path``."""
    fig = analysis_figure(motor, method, analysis)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def analysis_figure(motor: str, method: str, analysis: MotorAnalysis) -> Figure:
    """One motor's analysis figure (see the module docstring)."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    shape, dist = analysis.shape, analysis.disturbance
    fig = Figure(figsize=(11, 8.5), dpi=100, layout="constrained")
    (st_ax, ny_ax), (dy_ax, du_ax) = fig.subplots(2, 2)

    f = shape.freq_hz
    st_ax.semilogx(f, 20 * np.log10(shape.sensitivity), color="tab:blue", label="|S| = |1/(1+L)|")
    st_ax.semilogx(f, 20 * np.log10(shape.complementary), color="tab:orange",
                   label="|T| = |L/(1+L)|")  # fmt: skip
    ms, ms_hz = shape.sensitivity_peak, shape.sensitivity_peak_hz
    mt, mt_hz = shape.complementary_peak, shape.complementary_peak_hz
    st_ax.plot([ms_hz], [20 * np.log10(ms)], "o", color="tab:blue",
               label=f"Ms = {sig(ms)} ({_db(ms)} dB) at {sig(ms_hz)} Hz")  # fmt: skip
    f_low = 0.1  # Hz: the left edge; a peak at 0 Hz (integral action: T = 1) is drawn there
    mt_at = max(mt_hz, f_low)
    st_ax.plot([mt_at], [20 * np.log10(mt)], "s", color="tab:orange", clip_on=False,
               label=f"Mt = {sig(mt)} ({_db(mt)} dB) at {sig(mt_hz)} Hz")  # fmt: skip
    st_ax.axhline(0.0, color="0.4", lw=0.8)
    st_ax.set_ylim(max(-60.0, float(np.min(20 * np.log10(shape.sensitivity))) - 3.0), 12.0)
    st_ax.set_xlim(f_low, f[-1])
    st_ax.set_xlabel("frequency (Hz)")
    st_ax.set_ylabel("magnitude (dB)")
    st_ax.set_title("sensitivity S and complementary sensitivity T", fontsize=10)
    st_ax.legend(loc="lower right", fontsize=8)

    loop = shape.loop
    ny_ax.plot(
        loop.real, loop.imag, color="tab:blue", label="L(z), z = exp(j2πf·Ts), f = 0 → Nyquist"
    )
    ny_ax.plot(loop.real, -loop.imag, color="tab:blue", ls="--", lw=0.8, label="mirror (ω < 0)")
    ny_ax.plot([-1.0], [0.0], "+", color="tab:red", ms=12, mew=2, label="−1")
    ny_ax.add_patch(Circle((-1.0, 0.0), 1.0 / ms, fill=False, color="tab:red", ls=":",
                           label=f"radius 1/Ms = {sig(1.0 / ms)}"))  # fmt: skip
    ny_ax.add_patch(Circle((0.0, 0.0), 1.0, fill=False, color="0.6", lw=0.8, label="|L| = 1"))
    ny_ax.set_xlim(-3.0, 1.5)
    ny_ax.set_ylim(-2.25, 2.25)
    ny_ax.set_aspect("equal", adjustable="box")
    ny_ax.axhline(0.0, color="0.6", lw=0.6)
    ny_ax.axvline(0.0, color="0.6", lw=0.6)
    ny_ax.set_xlabel("Re L")
    ny_ax.set_ylabel("Im L")
    ny_ax.set_title("Nyquist curve of the loop L broken at the plant input", fontsize=10)
    ny_ax.legend(loc="upper left", fontsize=8)

    t_ms = dist.time_s * 1e3
    band = dist.recovery_band_rad_s
    peak, i = dist.peak_deviation_rad_s, dist.peak_index
    recovery = dist.recovery_time_s
    dy_ax.fill_between(t_ms, -band, band, color="0.85",
                       label=f"recovered: within ±{sig(band, 2)} rad/s (2 % of the peak)")  # fmt: skip
    dy_ax.plot(t_ms, dist.speed_rad_s, color="tab:blue", label="speed deviation")
    dy_ax.plot([t_ms[i]], [peak], "o", color="tab:red",
               label=f"peak {sig(peak)} rad/s at {t_ms[i]:.0f} ms")  # fmt: skip
    if recovery is not None:
        dy_ax.axvline(recovery * 1e3, color="tab:green", ls="--", lw=0.9,
                      label=f"recovery {recovery * 1e3:.0f} ms")  # fmt: skip
    end_ms = min(t_ms[-1], 3.0 * 1e3 * (recovery or dist.time_s[-1] / 3.0))
    dy_ax.set_xlim(0.0, max(end_ms, 100.0))
    dy_ax.set_xlabel("time since the step (ms)")
    dy_ax.set_ylabel("speed (rad/s)")
    dy_ax.set_title(f"load disturbance: {sig(dist.disturbance_v)} V step at the plant input",
                    fontsize=10)  # fmt: skip
    dy_ax.legend(loc="upper right", fontsize=8)

    du_ax.plot(t_ms, dist.voltage_v, color="tab:purple", label="controller's voltage u")
    du_ax.axhline(-dist.disturbance_v, color="0.3", ls=":", label="−d (full rejection)")
    du_ax.set_xlim(dy_ax.get_xlim())
    du_ax.set_xlabel("time since the step (ms)")
    du_ax.set_ylabel("voltage (V)")
    du_ax.set_title("the controller's answer", fontsize=10)
    du_ax.legend(loc="upper right", fontsize=8)
    for ax in (st_ax, ny_ax, dy_ax, du_ax):
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"Motor {motor}: {method} design, loop analysis")
    return fig
