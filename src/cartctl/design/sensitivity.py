"""Sensitivity S = 1/(1 + L) and complementary sensitivity T = L/(1 + L) of a designed loop.

Where it sits: after a design, for ``cartctl design`` (terminal, ``--json``, ``--report``). The
loop is broken at the plant input and the controller is the whole controller as the loop runs it
(:mod:`cartctl.design.controller_ss`: the PI, the PI on its Kalman estimate, or state feedback on
the estimate with its integral action)::

    L(z) = C_fb(z) · G(z) · z^(−extra),     C_fb = −U/Y (r = 0)

with G the model (its own delay nk included) and ``extra`` the design's ticks of delay beyond it:
the loop delay the controller was designed for. For a single loop L is the same wherever it is
broken. Ms = max|S| is the inverse of the shortest distance from L to −1 (the circle of radius
1/Ms around −1 touches the Nyquist curve): python-control's stability margin, through
:func:`cartctl.design.loop.loop_analysis`. Mt = max|T| is found on a frequency grid up to Nyquist
and refined with :func:`scipy.optimize.minimize_scalar`. Pure: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from cartctl.design.controller_ss import ControllerStateSpace
from cartctl.design.loop import loop_analysis
from cartctl.model import ArxModel

__all__ = ["LoopShape", "loop_shape"]

_GRID_POINTS = 2000
_LOW_HZ = 1e-3
"""Lowest frequency of the grid (Hz): an integrator puts L's pole at 0 Hz (z = 1)."""


@dataclass(frozen=True, eq=False)
class LoopShape:
    """The open loop L on a frequency grid, with the peaks of |S| and |T|.

    Attributes
    ----------
    freq_hz : ndarray, shape (n,)
        From 1 mHz to Nyquist (Hz), logarithmically spaced.
    loop : ndarray of complex, shape (n,)
        L(e^{j2πf·Ts}).
    sensitivity_peak, complementary_peak : float
        Ms = max|S|, Mt = max|T| (absolute).
    sensitivity_peak_hz, complementary_peak_hz : float
        Where they are (Hz); 0 when |T| is largest at 0 Hz (integral action: T(1) = 1).
    """

    freq_hz: NDArray[np.float64]
    loop: NDArray[np.complex128]
    sensitivity_peak: float
    sensitivity_peak_hz: float
    complementary_peak: float
    complementary_peak_hz: float

    @property
    def sensitivity(self) -> NDArray[np.float64]:
        """|S| on the grid."""
        return np.abs(1.0 / (1.0 + self.loop))

    @property
    def complementary(self) -> NDArray[np.float64]:
        """|T| on the grid."""
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


def loop_response(
    controller: ControllerStateSpace,
    model: ArxModel,
    extra_delay_ticks: int,
    freq_hz: NDArray[np.float64],
) -> NDArray[np.complex128]:
    """L(e^{j2πf·Ts}) = C_fb·G·z^(−extra) at the frequencies ``freq_hz`` (Hz)."""
    z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * model.period_s)
    plant = model.response_at(z)
    return controller.feedback_response(z) * plant * z ** (-int(extra_delay_ticks))


def _peak(
    value: Any, freq_hz: NDArray[np.float64], on_grid: NDArray[np.float64]
) -> tuple[float, float]:
    """(max, where) of ``value(f)``: the grid's best point, refined between its neighbours."""
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
    """S and T of the loop a controller was designed for, with their peaks (Ms from
    :func:`~cartctl.design.loop.loop_analysis`).

    Parameters
    ----------
    controller : ControllerStateSpace
        The controller as the loop runs it.
    model : ArxModel
        The plant model (V → rad/s, its delay nk included).
    extra_delay_ticks : int
        Ticks of loop delay beyond the model's (the design's ``--extra-delay``).
    """
    nyquist = 0.5 / model.period_s
    freq = np.geomspace(_LOW_HZ, nyquist, _GRID_POINTS)
    loop = loop_response(controller, model, extra_delay_ticks, freq)

    def t_at(f: float) -> float:
        ell = loop_response(controller, model, extra_delay_ticks, np.array([f]))[0]
        return float(abs(ell / (1.0 + ell)))

    mt, mt_hz = _peak(t_at, freq, np.abs(loop / (1.0 + loop)))
    margins = loop_analysis(*controller.feedback_tf(), model, extra_delay_ticks)
    ms, ms_hz = margins["sensitivity_peak"], margins["sensitivity_peak_hz"]
    return LoopShape(freq, loop, ms, ms_hz, mt, mt_hz)
