"""The report of a design's loop analysis (:func:`~cartctl.design.make.analyse_motor`): the
figures of ``design --report DIR`` (matplotlib's Agg canvas) and the numbers as the command prints
them (:mod:`cartctl.measures.numfmt`'s rules)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cartctl.data.outputs import writing
from cartctl.design.analysis import settling_bound
from cartctl.design.controller_ss import controller_state_space
from cartctl.design.make import Designs, MotorAnalysis
from cartctl.measures.numfmt import format_column, format_fixed

if TYPE_CHECKING:
    from matplotlib.figure import Figure


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


def design_figure(motor: str, designs: Designs) -> Figure:
    """One motor's figure: |L| and ∠L with the margins of its ``design --json`` entry, the
    simulated step's speed and voltage beside the time-optimal ones on the same loop."""
    from matplotlib.figure import Figure

    model, step, request = designs.models[motor], designs.steps[motor], designs.request
    entry = designs.motors[motor].entry
    extra_delay_ticks, voltage_limit_v = request.extra_delay_ticks, request.voltage_limit_v
    fig = Figure(figsize=(11, 8.5), dpi=110, layout="constrained")
    axes = fig.subplots(2, 2, sharex="col")
    freq = np.logspace(-1, np.log10(0.5 / model.period_s * 0.999), 600)
    z = np.exp(2j * np.pi * freq * model.period_s)
    c = controller_state_space(  # the whole controller: a PI's estimator too
        request.method, designs.motors[motor].file_entry, model.period_s
    ).feedback_response(z)
    loop = c * model.response_at(z) * z ** (-extra_delay_ticks)
    mag_ax, ph_ax = axes[0, 0], axes[1, 0]
    mag_ax.semilogx(freq, 20 * np.log10(np.abs(loop)), color="tab:blue")
    mag_ax.axhline(0.0, color="0.4", lw=0.8)
    ph_ax.semilogx(freq, np.degrees(np.unwrap(np.angle(loop))), color="tab:blue")
    ph_ax.axhline(-180.0, color="0.4", lw=0.8)
    fc, pm, gm = (entry.get(k) for k in ("crossover_hz", "phase_margin_deg", "gain_margin_db"))
    if fc:
        for ax in (mag_ax, ph_ax):
            ax.axvline(fc, color="tab:red", ls="--", lw=0.9)
    if fc and pm is not None:  # a crossover has a phase margin
        ph_ax.plot([fc, fc], [-180.0, -180.0 + pm], color="tab:red", lw=2.5)
        # the note in axes coordinates, lower left, where the phase curve never is
        ph_ax.text(0.03, 0.05, f"phase margin {pm:.1f}° at {fc:.2f} Hz", color="tab:red",
                   transform=ph_ax.transAxes, ha="left", va="bottom")  # fmt: skip
    gm_text = "∞" if gm is None else f"{gm:.1f} dB"
    _dress(mag_ax, None, "magnitude (dB)", f"open loop L = C·G (gain margin {gm_text})")
    _dress(ph_ax, "frequency (Hz)", "phase (deg)")
    sp_ax, v_ax = axes[0, 1], axes[1, 1]
    r = float(step.reference_rad_s[-1])
    bound = settling_bound(
        model, r, voltage_limit_v=voltage_limit_v, extra_delay_ticks=extra_delay_ticks
    )
    band = bound.band_rad_s
    t_bound = np.arange(bound.speed_rad_s.size) * model.period_s
    sp_ax.plot(step.time_s, step.reference_rad_s, color="0.3", ls=":", label="reference")
    sp_ax.fill_between(step.time_s, r - band, r + band, color="0.85",
                       label=f"settling band ±{band:.2f} rad/s")  # fmt: skip
    sp_ax.plot(step.time_s, step.speed_rad_s, color="tab:blue", label="speed (model)")
    sp_ax.plot(step.time_s, step.estimate_rad_s, color="tab:green", lw=0.9, ls="--",
               label="controller's speed")  # fmt: skip
    sp_ax.plot(t_bound, bound.speed_rad_s, color="tab:orange", lw=0.9,
               label=f"time-optimal, loop delay {bound.loop_delay_ticks} tick(s) "
                     f"({bound.settling_time_s * 1e3:.0f} ms)")  # fmt: skip
    settle = step.info.settling_time_s
    title = f"{r:g} rad/s step: overshoot {step.info.overshoot_percent or 0:.1f} %, settling " + (
        "—" if settle is None else f"{settle * 1e3:.0f} ms"
    )
    _dress(sp_ax, None, "speed (rad/s)", title, "lower right")
    v_ax.plot(step.time_s, step.voltage_v, color="tab:purple", label="controller")
    v_ax.plot(t_bound, bound.voltage_v, color="tab:orange", lw=0.9, label="time-optimal")
    for sign in (1, -1):
        v_ax.axhline(sign * voltage_limit_v, color="tab:red", lw=0.8, ls="--")
    v_ax.set_xlim(0, min(step.time_s[-1], 0.5))
    _dress(v_ax, "time (s)", "voltage (V)", None, "upper right")
    fig.suptitle(f"Motor {motor}: {request.method} design")
    return fig


def write_report(out_dir: str | Path, designs: Designs) -> list[Path]:
    """``design_X.png`` (:func:`design_figure`) and ``analysis_X.png`` (:func:`analysis_figure`)
    per motor; returns their paths."""
    out, paths = Path(out_dir), []
    for m, analysis in designs.analyses.items():
        figures = {
            "design": design_figure(m, designs),
            "analysis": analysis_figure(m, designs.request.method, analysis),
        }
        for name, figure in figures.items():
            paths.append(out / f"{name}_{m}.png")
            with writing(paths[-1]):
                figure.savefig(paths[-1])
    return paths


def _dress(
    ax: Any, xlabel: str | None, ylabel: str, title: str | None = None, legend: str | None = None
) -> None:
    """A panel's labels, title (10 pt), legend (8 pt, at ``legend``) and grid."""
    if xlabel:
        ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title, fontsize=10)
    if legend:
        ax.legend(loc=legend, fontsize=8)
    ax.grid(True, which="both", alpha=0.3)


def _db(value: float) -> str:
    return format_fixed(20.0 * float(np.log10(value)), 2)


def analysis_figure(motor: str, method: str, analysis: MotorAnalysis) -> Figure:
    """One motor's analysis figure (see the module docstring)."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    shape, dist = analysis, analysis.disturbance
    fig = Figure(figsize=(11, 8.5), dpi=100, layout="constrained")
    (st_ax, ny_ax), (dy_ax, du_ax) = fig.subplots(2, 2)

    f, loop = shape.freq_hz, shape.loop
    s_db = 20 * np.log10(np.abs(1.0 / (1.0 + loop)))
    st_ax.semilogx(f, s_db, color="tab:blue", label="|S| = |1/(1+L)|")
    st_ax.semilogx(f, 20 * np.log10(np.abs(loop / (1.0 + loop))), color="tab:orange",
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
    st_ax.set_ylim(max(-60.0, float(np.min(s_db)) - 3.0), 12.0)
    st_ax.set_xlim(f_low, f[-1])
    _dress(st_ax, "frequency (Hz)", "magnitude (dB)",
           "sensitivity S and complementary sensitivity T", "lower right")  # fmt: skip

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
    _dress(ny_ax, "Re L", "Im L", "Nyquist curve of the loop L broken at the plant input",
           "upper left")  # fmt: skip

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
    title = f"load disturbance: {sig(dist.disturbance_v)} V step at the plant input"
    _dress(dy_ax, "time since the step (ms)", "speed (rad/s)", title, "upper right")

    du_ax.plot(t_ms, dist.voltage_v, color="tab:purple", label="controller's voltage u")
    du_ax.axhline(-dist.disturbance_v, color="0.3", ls=":", label="−d (full rejection)")
    du_ax.set_xlim(dy_ax.get_xlim())
    _dress(du_ax, "time since the step (ms)", "voltage (V)", "the controller's answer",
           "upper right")  # fmt: skip
    fig.suptitle(f"Motor {motor}: {method} design, loop analysis")
    return fig
