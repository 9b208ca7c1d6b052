"""The loop analysis of designs, per motor: margins, S and T with their peaks, the
load-disturbance step, and the damping of each closed-loop pole; for ``design --json`` and the
report's figures.

The controller is taken whole, as the loop runs it (:mod:`cartctl.design.controller_ss`), broken
at the plant input: L = C_fb·G·z^(−extra), C_fb = −U/Y (r = 0), S = 1/(1 + L), T = L/(1 + L).
Margins and Ms = max|S| are python-control's (:func:`~cartctl.design.analysis.loop_analysis`); Mt = max|T| is found on a
frequency grid up to Nyquist, refined by ``minimize_scalar``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.analysis import (
    DEFAULT_DISTURBANCE_V,
    DisturbanceResponse,
    loop_analysis,
    simulate_disturbance,
)
from cartctl.design.controller_ss import ControllerStateSpace, controller_state_space
from cartctl.design.make import Designs
from cartctl.model import ArxModel, pole_damping

LIGHT_DAMPING = 0.1  # a closed-loop pole with a damping ratio ζ below this rings: a warning
_GRID_POINTS = 2000
_LOW_HZ = 1e-3  # the grid's lowest frequency (Hz): an integrator puts L's pole at 0 Hz


@dataclass(frozen=True, eq=False)
class LoopShape:
    """The open loop L on a frequency grid (``freq_hz``, 1 mHz to Nyquist), with the peaks
    Ms = max|S| and Mt = max|T| and where they are (Hz; 0 for T(1) = 1 of integral action)."""

    freq_hz: NDArray[np.float64]
    loop: NDArray[np.complex128]
    sensitivity_peak: float
    sensitivity_peak_hz: float
    complementary_peak: float
    complementary_peak_hz: float

    @property
    def sensitivity(self) -> NDArray[np.float64]:  # |S| on the grid
        return np.abs(1.0 / (1.0 + self.loop))

    @property
    def complementary(self) -> NDArray[np.float64]:  # |T| on the grid
        return np.abs(self.loop / (1.0 + self.loop))

    def to_dict(self) -> dict[str, Any]:
        """The ``design --json`` keys (added to each motor's entry)."""
        return {
            "sensitivity_peak_db": 20.0 * math.log10(self.sensitivity_peak),
            "sensitivity_peak_hz": self.sensitivity_peak_hz,
            "complementary_peak": self.complementary_peak,
            "complementary_peak_db": 20.0 * math.log10(self.complementary_peak),
            "complementary_peak_hz": self.complementary_peak_hz,
            "sensitivity_distance": 1.0 / self.sensitivity_peak,
        }


def _loop_response(
    controller: ControllerStateSpace, model: ArxModel, extra: int, freq_hz: NDArray[np.float64]
) -> NDArray[np.complex128]:
    z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * model.period_s)
    return controller.feedback_response(z) * model.response_at(z) * z ** (-int(extra))


def _peak(
    value: Callable[[float], float], freq_hz: NDArray[np.float64], on_grid: NDArray[np.float64]
) -> tuple[float, float]:
    """(max, where) of ``value(f)``: the grid's best point, refined between its neighbours."""
    from scipy import optimize

    i = int(np.argmax(on_grid))
    best, where = float(on_grid[i]), float(freq_hz[i])
    lo, hi = freq_hz[max(i - 1, 0)], freq_hz[min(i + 1, freq_hz.size - 1)]
    if hi > lo:
        res = optimize.minimize_scalar(
            lambda f: -value(f), bounds=(lo, hi), method="bounded", options={"xatol": 1e-9}
        )
        if res.success and -res.fun > best:
            best, where = float(-res.fun), float(res.x)
    if i == 0:  # largest at the bottom of the grid: at 0 Hz, where the integrator puts it
        where = 0.0
    return best, where


def loop_shape(
    controller: ControllerStateSpace, model: ArxModel, extra_delay_ticks: int = 0
) -> LoopShape:
    """S and T of the loop a controller was designed for, with their peaks."""
    freq = np.geomspace(_LOW_HZ, 0.5 / model.period_s, _GRID_POINTS)
    loop = _loop_response(controller, model, extra_delay_ticks, freq)

    def t_at(f: float) -> float:
        ell = _loop_response(controller, model, extra_delay_ticks, np.array([f]))[0]
        return float(abs(ell / (1.0 + ell)))

    mt, mt_hz = _peak(t_at, freq, np.abs(loop / (1.0 + loop)))
    margins = loop_analysis(*controller.feedback_tf(), model, extra_delay_ticks)
    ms, ms_hz = margins["sensitivity_peak"], margins["sensitivity_peak_hz"]
    return LoopShape(freq, loop, ms, ms_hz, mt, mt_hz)


def pole_table(poles: Iterable[list[float]], period_s: float) -> list[dict[str, Any]]:
    """Per discrete pole [re, im], ``{"re", "im", "damping", "freq_hz"}`` (``pole_damping``)."""
    rows = []
    for re, im in poles:
        damping, freq_hz = pole_damping(complex(re, im), period_s)
        rows.append({"re": re, "im": im, "damping": damping, "freq_hz": freq_hz})
    return rows


def damping_warning(pole_table: list[dict[str, Any]], motor: str) -> str | None:
    """One line naming motor ``motor``'s least damped pole when its ζ is below ``LIGHT_DAMPING``;
    None when every ζ is at least that (or undefined: z = 0, z = 1)."""
    light = [r for r in pole_table if r["damping"] is not None and r["damping"] < LIGHT_DAMPING]
    if not light:
        return None
    worst = min(light, key=lambda r: r["damping"])
    z = f"{worst['re']:.4f}" + ("" if worst["im"] == 0.0 else f" ± {abs(worst['im']):.4f}j")
    freq = "" if worst["freq_hz"] is None else f" at {worst['freq_hz']:.2f} Hz"
    others = len({(r["re"], abs(r["im"])) for r in light}) - 1
    more = f" ({others} more pole(s) below {LIGHT_DAMPING:g})" if others else ""
    return (
        f"motor {motor}: closed-loop pole z = {z} has damping ζ = {worst['damping']:.3f} < "
        f"{LIGHT_DAMPING:g}{more}: the loop rings{freq} for many periods"
    )


@dataclass(frozen=True, eq=False)
class MotorAnalysis:
    """One motor's loop analysis: the controller as the loop runs it, L, S and T, the simulated
    load-disturbance step, and the pole table."""

    controller: ControllerStateSpace
    shape: LoopShape
    disturbance: DisturbanceResponse
    pole_table: list[dict[str, Any]]
    motor: str = "a"

    def entry(self) -> dict[str, Any]:
        """The keys this analysis adds to (or replaces in) a motor's ``design --json`` entry;
        ``sensitivity_peak`` is the loop's as it runs (the PI's with its Kalman estimator)."""
        return {
            "sensitivity_peak": self.shape.sensitivity_peak,
            **self.shape.to_dict(),
            "disturbance": self.disturbance.to_dict(),
            "closed_loop_pole_table": self.pole_table,
            "warnings": self.warnings,
        }

    @property
    def warnings(self) -> list[str]:
        """One line per warning about this loop."""
        line = damping_warning(self.pole_table, self.motor)
        return [] if line is None else [line]


def analyse_designs(
    designs: Designs, *, disturbance_v: float = DEFAULT_DISTURBANCE_V
) -> dict[str, MotorAnalysis]:
    """The analysis of every motor of ``designs``, with a load step of ``disturbance_v`` (V)."""
    extra = designs.request.extra_delay_ticks
    out: dict[str, MotorAnalysis] = {}
    for m, made in designs.motors.items():
        model = designs.models[m]
        ss = controller_state_space(designs.request.method, made.file_entry, model.period_s)
        dist = simulate_disturbance(
            made.controller, model, disturbance_v=disturbance_v, extra_delay_ticks=extra
        )
        table = pole_table(made.entry["closed_loop_poles"], model.period_s)
        out[m] = MotorAnalysis(ss, loop_shape(ss, model, extra), dist, table, m)
    return out
