"""``cartctl design --report DIR``: the open-loop Bode plot with its margins and the simulated step
beside the time-optimal one, per motor (PNG, matplotlib's Agg canvas).

The time-optimal step is computed on the loop the design is for (the model with the design's extra
delay, as the simulated step), and both are judged in the same settling band, max(2 %, one encoder
count per tick) (:mod:`cartctl.design.limit`)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cartctl.design.analysis import StepAnalysis
from cartctl.design.limit import in_settling_band, settling_bound
from cartctl.model import ArxModel

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _loop_response(
    entry: Mapping[str, Any], model: ArxModel, extra: int, freq_hz: np.ndarray
) -> np.ndarray:
    z = np.exp(2j * np.pi * freq_hz * model.period_s)
    c = np.polyval(entry["controller_num"], z) / np.polyval(entry["controller_den"], z)
    g = model.response_at(z)
    return c * g * z ** (-extra)


def design_figure(
    motor: str,
    model: ArxModel,
    entry: Mapping[str, Any],
    step: StepAnalysis,
    *,
    extra_delay_ticks: int,
    voltage_limit_v: float,
) -> Figure:
    """One motor's figure: |L| and ∠L with the margins, then speed and voltage of the step.

    The step is drawn beside the time-optimal one on the same loop (``extra_delay_ticks`` beyond
    the model's delay), its settling measured in the bound's band.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 8.5), dpi=110, layout="constrained")
    axes = fig.subplots(2, 2, sharex="col")
    freq = np.logspace(-1, np.log10(0.5 / model.period_s * 0.999), 600)
    loop = _loop_response(entry, model, extra_delay_ticks, freq)
    mag_ax, ph_ax = axes[0, 0], axes[1, 0]
    mag_ax.semilogx(freq, 20 * np.log10(np.abs(loop)), color="tab:blue")
    mag_ax.axhline(0.0, color="0.4", lw=0.8)
    ph_ax.semilogx(freq, np.degrees(np.unwrap(np.angle(loop))), color="tab:blue")
    ph_ax.axhline(-180.0, color="0.4", lw=0.8)
    fc, pm, gm = (
        entry.get("crossover_hz"),
        entry.get("phase_margin_deg"),
        entry.get("gain_margin_db"),
    )
    if fc:
        for ax in (mag_ax, ph_ax):
            ax.axvline(fc, color="tab:red", ls="--", lw=0.9)
    if fc and pm is not None:  # a crossover has a phase margin
        ph_ax.plot([fc, fc], [-180.0, -180.0 + pm], color="tab:red", lw=2.5)
        # the note in axes coordinates, lower left, where the phase curve never is
        ph_ax.text(0.03, 0.05, f"phase margin {pm:.1f}° at {fc:.2f} Hz", color="tab:red",
                   transform=ph_ax.transAxes, ha="left", va="bottom")  # fmt: skip
    mag_ax.set_title(
        f"open loop L = C·G (gain margin {'∞' if gm is None else f'{gm:.1f} dB'})", fontsize=10
    )
    mag_ax.set_ylabel("magnitude (dB)")
    ph_ax.set_ylabel("phase (deg)")
    ph_ax.set_xlabel("frequency (Hz)")
    sp_ax, v_ax = axes[0, 1], axes[1, 1]
    r = float(step.reference_rad_s[-1])
    bound = settling_bound(
        model, r, voltage_limit_v=voltage_limit_v, extra_delay_ticks=extra_delay_ticks
    )
    band = bound.band_rad_s
    step = in_settling_band(step, model.period_s)
    t_bound = np.arange(bound.speed_rad_s.size) * model.period_s
    sp_ax.plot(step.time_s, step.reference_rad_s, color="0.3", ls=":", label="reference")
    sp_ax.fill_between(step.time_s, r - band, r + band, color="0.85",
                       label=f"settling band ±{band:.2f} rad/s")  # fmt: skip
    sp_ax.plot(step.time_s, step.speed_rad_s, color="tab:blue", label="speed (model)")
    sp_ax.plot(
        step.time_s,
        step.estimate_rad_s,
        color="tab:green",
        lw=0.9,
        ls="--",
        label="controller's speed",
    )
    sp_ax.plot(t_bound, bound.speed_rad_s, color="tab:orange", lw=0.9,
               label=f"time-optimal, loop delay {bound.loop_delay_ticks} tick(s) "
                     f"({bound.settling_time_s * 1e3:.0f} ms)")  # fmt: skip
    settle = step.info.settling_time_s
    sp_ax.set_title(
        f"{r:g} rad/s step: overshoot {step.info.overshoot_percent or 0:.1f} %, settling "
        + ("—" if settle is None else f"{settle * 1e3:.0f} ms"),
        fontsize=10,
    )
    sp_ax.set_ylabel("speed (rad/s)")
    sp_ax.legend(loc="lower right", fontsize=8)
    v_ax.plot(step.time_s, step.voltage_v, color="tab:purple", label="controller")
    v_ax.plot(t_bound, bound.voltage_v, color="tab:orange", lw=0.9, label="time-optimal")
    for sign in (1, -1):
        v_ax.axhline(sign * voltage_limit_v, color="tab:red", lw=0.8, ls="--")
    v_ax.set_ylabel("voltage (V)")
    v_ax.set_xlabel("time (s)")
    v_ax.set_xlim(0, min(step.time_s[-1], 0.5))
    v_ax.legend(loc="upper right", fontsize=8)
    for ax in axes.flat:
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"Motor {motor}: {entry.get('method', 'controller')} design")
    return fig


def write_design_report(
    out_dir: str | Path,
    method: str,
    models: Mapping[str, ArxModel],
    entries: Mapping[str, Mapping[str, Any]],
    steps: Mapping[str, StepAnalysis],
    *,
    extra_delay_ticks: int,
    voltage_limit_v: float,
) -> list[Path]:
    """One PNG per motor (:func:`design_figure`), ``design_a.png`` …; returns their paths."""
    paths = []
    for m in entries:
        fig = design_figure(m, models[m], {**entries[m], "method": method}, steps[m],
                            extra_delay_ticks=extra_delay_ticks, voltage_limit_v=voltage_limit_v)  # fmt: skip
        paths.append(Path(out_dir) / f"design_{m}.png")
        paths[-1].parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(paths[-1])
    return paths
