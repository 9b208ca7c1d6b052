"""The physical limit: the fastest settling any voltage sequence within ±12 V allows on a model.

For a step of the speed reference from rest to ``r``, the model's output is linear in the voltage
sequence, y = T u with T the lower-triangular Toeplitz matrix of the impulse response. The question
"can the output be inside the ±2 % band from tick N on?" is then a linear feasibility problem:

    find u   with   |u[k]| ≤ U_max                         for all k,
                    |y[k] − r| ≤ 0.02 |r|                  for N ≤ k < N + M,

where the band must hold over a hold window of M ticks (default 2 s). The smallest feasible N,
found by bisection over linear programs (scipy.optimize.linprog, HiGHS), is the bound that no
controller can beat on this model. A controller's settling time is reported as a ratio to it. The
sequence returned is, among those settling at N, the one closest to the reference after N (least
Σ|y − r|), so that it can be drawn next to the controller's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import optimize
from scipy.linalg import toeplitz

from cartctl.errors import InputError
from cartctl.model import ArxModel


@dataclass(frozen=True)
class SettlingBound:
    """The time-optimal settling bound of a step on a model.

    Attributes
    ----------
    settling_time_s : float
        Smallest time from the step at which the output can be in the band for good (s).
    ticks : int
        The same, in ticks.
    voltage_v : ndarray, shape (n,)
        A voltage sequence that achieves it (V).
    speed_rad_s : ndarray, shape (n,)
        The model's response to that sequence (rad/s).
    """

    settling_time_s: float
    ticks: int
    voltage_v: NDArray[np.float64]
    speed_rad_s: NDArray[np.float64]


def _feasible(
    impulse: NDArray[np.float64], n_settle: int, hold: int, r: float, band: float, u_max: float
) -> NDArray[np.float64] | None:
    n = n_settle + hold
    t = toeplitz(impulse[:n], np.zeros(n))[n_settle:]  # rows: y[k] for k in [N, N + M)
    a_ub = np.vstack([t, -t])
    b_ub = np.concatenate([np.full(hold, r + band), np.full(hold, -(r - band))])
    res = optimize.linprog(
        np.zeros(n), A_ub=a_ub, b_ub=b_ub, bounds=[(-u_max, u_max)] * n, method="highs"
    )
    return res.x if res.status == 0 else None


def settling_bound(
    model: ArxModel,
    step_rad_s: float,
    *,
    voltage_limit_v: float = 12.0,
    band: float = 0.02,
    hold_s: float = 2.0,
    max_s: float = 3.0,
) -> SettlingBound:
    """Fastest 2 % settling of a speed step from rest that any admissible voltage allows.

    Parameters
    ----------
    model : ArxModel
        The motor model (stable, non-zero DC gain).
    step_rad_s : float
        Step size r (rad/s), non-zero.
    voltage_limit_v : float
        |u| bound (V).
    band : float
        Settling band as a fraction of |r| (0.02: the 2 % criterion).
    hold_s : float
        How long the output must stay in the band (s).
    max_s : float
        Longest settling time searched (s).

    Raises
    ------
    InputError
        The step cannot be held within the voltage limit at all (|r| above the DC gain × limit),
        or the model is unstable.
    """
    if not model.is_stable():
        raise InputError("the settling bound needs a stable model")
    gain = model.dc_gain()
    if step_rad_s == 0.0 or not math.isfinite(step_rad_s):
        raise InputError(f"step size must be a non-zero number of rad/s, got {step_rad_s}")
    if abs(step_rad_s) * (1 - band) > abs(gain) * voltage_limit_v:
        raise InputError(
            f"a {step_rad_s:g} rad/s step cannot be held within ±{voltage_limit_v:g} V: the model "
            f"reaches at most {abs(gain) * voltage_limit_v:.3g} rad/s"
        )
    ts = model.period_s
    hold = max(1, round(hold_s / ts))
    n_max = max(1, round(max_s / ts))
    impulse = model.simulate(np.r_[1.0, np.zeros(n_max + hold)])
    tol = band * abs(step_rad_s)
    lo, hi = 0, n_max  # infeasible at lo (nothing moves at tick 0 with nk ≥ 1), hi must be feasible
    best = _feasible(impulse, hi, hold, step_rad_s, tol, voltage_limit_v)
    if best is None:
        raise InputError(f"no admissible voltage settles this step within {max_s:g} s")
    while hi - lo > 1:
        mid = (lo + hi) // 2
        u = _feasible(impulse, mid, hold, step_rad_s, tol, voltage_limit_v)
        if u is None:
            lo = mid
        else:
            hi, best = mid, u
    best = _closest(impulse, hi, hold, step_rad_s, tol, voltage_limit_v, best)
    return SettlingBound(hi * ts, hi, best, model.simulate(best))


def _closest(
    impulse: NDArray[np.float64],
    n_settle: int,
    hold: int,
    r: float,
    band: float,
    u_max: float,
    fallback: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Among the sequences settling at N, the one with the least Σ|y − r| after N (a clean trace).

    Variables [u (n), t (M)]: minimise Σ t subject to −t ≤ y − r ≤ t and the band.
    """
    n = n_settle + hold
    t_mat = toeplitz(impulse[:n], np.zeros(n))[n_settle:]
    eye = np.eye(hold)
    zeros = np.zeros((hold, hold))
    a_ub = np.block([[t_mat, -eye], [-t_mat, -eye], [t_mat, zeros], [-t_mat, zeros]])
    b_ub = np.concatenate(
        [np.full(hold, r), np.full(hold, -r), np.full(hold, r + band), np.full(hold, band - r)]
    )
    cost = np.concatenate([np.zeros(n), np.ones(hold)])
    bounds = [(-u_max, u_max)] * n + [(0.0, None)] * hold
    res = optimize.linprog(cost, A_ub=a_ub, b_ub=b_ub, bounds=bounds, method="highs")
    return res.x[:n] if res.status == 0 else fallback
