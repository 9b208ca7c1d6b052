"""The physical limit: the fastest settling any voltage sequence within ±12 V allows on a model.

The plant is the model with the design's extra loop delay: input delay nk + d, the loop a design
made with ``--extra-delay d`` is for and the one its step is simulated on
(:func:`cartctl.design.analysis.simulate_step` with ``extra_delay_ticks=d``). Its loop delay, ticks
from a measurement to the voltage it leads to, is nk − 1 + d.

For a step of the speed reference from rest to ``r``, the plant's output is linear in the voltage
sequence, y = T u with T the lower-triangular Toeplitz matrix of the impulse response. The question
"can the output be inside the settling band from tick N on?" is then a linear feasibility problem:

    find u   with   |u[k]| ≤ U_max                         for all k,
                    |y[k] − r| ≤ max(0.02 |r|, q)          for N ≤ k < N + M,

where the band must hold over a hold window of M ticks (default 2 s). The band is the settling
rule of :func:`settling_band_rad_s`: 2 % of the step, but never narrower than one encoder count per
tick, q = (2π / 1792) / Ts (0.3506 rad/s at 10 ms), the resolution of the measured speed. The
smallest feasible N, found by bisection over linear programs (scipy.optimize.linprog, HiGHS), is
the bound that no controller can beat on this plant. A controller's settling time is reported as
a ratio to it, measured in the same band (:func:`in_settling_band`). The sequence returned is,
among those settling at N, the one closest to the reference after N (least Σ|y − r|), so that it
can be drawn next to the controller's.

Like with like: the bound is a whole number of ticks (the first sample from which every sample is
in the band), while a step's settling time interpolates the band crossing between two samples, so
a controller that matches the bound shows a ratio a little below 1 (by less than one tick).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import optimize
from scipy.linalg import toeplitz

from cartctl.cart import SUPPLY_V, encoder_quantum_rad_s
from cartctl.design.analysis import StepAnalysis
from cartctl.errors import InputError
from cartctl.measures.stepinfo import SETTLING_FRACTION, settling_half_width, step_info
from cartctl.model import ArxModel


def settling_band_rad_s(
    step_rad_s: float,
    period_s: float,
    *,
    fraction: float = SETTLING_FRACTION,
    quantum_rad_s: float | None = None,
) -> float:
    """Half-width of the settling band of a speed step: max(fraction · |r|, q).

    The rule of :func:`cartctl.measures.stepinfo.settling_half_width` with the floor q of a measured wheel
    speed, one encoder count per tick (:func:`cartctl.cart.encoder_quantum_rad_s`): a band
    narrower than that (2 % of steps below 17.5 rad/s at 10 ms) would judge the encoder rather
    than the controller. The run summary judges its steps in the same band.

    Parameters
    ----------
    step_rad_s : float
        Step size r (rad/s), non-zero.
    period_s : float
        Tick Ts (s), for the default quantum.
    fraction : float
        Band as a fraction of |r|, in (0, 1).
    quantum_rad_s : float, optional
        The floor q (rad/s, ≥ 0); default one encoder count per tick. 0 gives the fraction alone.

    Returns
    -------
    float
        The band's half-width (rad/s).

    Raises
    ------
    InputError
        A zero or non-finite step, a fraction outside (0, 1), a negative floor, or a step no
        larger than its own band (it would count as settled at rest: there is no bound to give).
    """
    if step_rad_s == 0.0 or not math.isfinite(step_rad_s):
        raise InputError(f"step size must be a non-zero number of rad/s, got {step_rad_s}")
    q = encoder_quantum_rad_s(period_s) if quantum_rad_s is None else float(quantum_rad_s)
    band = settling_half_width(step_rad_s, q, fraction)
    if band >= abs(step_rad_s):
        raise InputError(
            f"a {step_rad_s:g} rad/s step lies within its own settling band (±{band:.4g} rad/s, "
            "one encoder count per tick): use a larger step"
        )
    return band


def in_settling_band(step: StepAnalysis, period_s: float) -> StepAnalysis:
    """The same simulated step with its metrics measured in the band of :func:`settling_band_rad_s`.

    Only the settling time can change (rise, overshoot and peak do not depend on the band). This is
    how a design's step is measured against its :func:`settling_bound`.

    Parameters
    ----------
    step : StepAnalysis
        A step from rest to ``step.reference_rad_s[-1]`` at ``step.time_s[0]``.
    period_s : float
        Tick Ts (s), for the encoder quantum.
    """
    r = float(step.reference_rad_s[-1])
    settling_band_rad_s(r, period_s)  # refuses a step inside its own band, as the bound does
    info = step_info(step.time_s, step.speed_rad_s, reference=r, initial=0.0,
                     onset_s=float(step.time_s[0]), settling_floor=encoder_quantum_rad_s(period_s))  # fmt: skip
    return replace(step, info=info)


@dataclass(frozen=True)
class SettlingBound:
    """The time-optimal settling bound of a step on a model (with the design's extra delay).

    Attributes
    ----------
    settling_time_s : float
        Smallest time from the step at which the output can be in the band for good (s).
    ticks : int
        The same, in ticks.
    voltage_v : ndarray, shape (n,)
        A voltage sequence that achieves it (V).
    speed_rad_s : ndarray, shape (n,)
        The delayed plant's response to that sequence (rad/s).
    loop_delay_ticks : int
        The loop delay the bound is for: nk − 1 + extra delay (ticks).
    band_rad_s : float
        Half-width of the settling band used (rad/s).
    """

    settling_time_s: float
    ticks: int
    voltage_v: NDArray[np.float64]
    speed_rad_s: NDArray[np.float64]
    loop_delay_ticks: int
    band_rad_s: float


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
    voltage_limit_v: float = SUPPLY_V,
    extra_delay_ticks: int = 0,
    band: float = SETTLING_FRACTION,
    quantum_rad_s: float | None = None,
    hold_s: float = 2.0,
    max_s: float = 3.0,
) -> SettlingBound:
    """Fastest settling of a speed step from rest that any admissible voltage allows.

    Computed on the model with ``extra_delay_ticks`` more ticks of input delay, the loop a design
    with that extra delay is for, in the band max(``band`` · |r|, q) (:func:`settling_band_rad_s`).
    A pure delay shifts every sequence, so the bound with d extra ticks is the bound without plus
    d ticks.

    Parameters
    ----------
    model : ArxModel
        The motor model (stable, non-zero DC gain).
    step_rad_s : float
        Step size r (rad/s), non-zero.
    voltage_limit_v : float
        |u| bound (V).
    extra_delay_ticks : int
        Ticks of loop delay beyond the model's (a design's ``--extra-delay``).
    band : float
        Settling band as a fraction of |r| (0.02: the 2 % criterion).
    quantum_rad_s : float, optional
        Narrowest band (rad/s); default one encoder count per tick. 0: the fraction alone.
    hold_s : float
        How long the output must stay in the band (s).
    max_s : float
        Longest settling time searched (s).

    Raises
    ------
    InputError
        The step cannot be held within the voltage limit at all (|r| − band above the DC gain ×
        limit), the step lies within its own band, the extra delay is not a whole number >= 0, or
        the model is unstable.
    """
    return _settling_bound(model, float(step_rad_s), float(voltage_limit_v), extra_delay_ticks,
                           float(band), quantum_rad_s, float(hold_s), float(max_s))  # fmt: skip


@functools.lru_cache(maxsize=256)
def _settling_bound(
    model: ArxModel,
    step_rad_s: float,
    voltage_limit_v: float,
    extra_delay_ticks: int,
    band: float,
    quantum_rad_s: float | None,
    hold_s: float,
    max_s: float,
) -> SettlingBound:
    """:func:`settling_bound`, cached: a bound is a function of its arguments alone, and design,
    tune and commission ask for the same one many times (each is a search of linear programs).
    The arrays it returns are read-only, as every caller shares them."""
    plant = model.with_extra_delay(extra_delay_ticks)
    if not plant.is_stable():
        raise InputError("the settling bound needs a stable model")
    gain = plant.dc_gain()
    tol = settling_band_rad_s(
        step_rad_s, plant.period_s, fraction=band, quantum_rad_s=quantum_rad_s
    )
    if abs(step_rad_s) - tol > abs(gain) * voltage_limit_v:
        raise InputError(
            f"a {step_rad_s:g} rad/s step cannot be held within ±{voltage_limit_v:g} V: the model "
            f"reaches at most {abs(gain) * voltage_limit_v:.3g} rad/s"
        )
    ts = plant.period_s
    hold = max(1, round(hold_s / ts))
    n_max = max(1, round(max_s / ts))
    impulse = plant.simulate(np.r_[1.0, np.zeros(n_max + hold)])
    # feasibility only grows with N (a sequence settling at N settles at N + 1): gallop up from
    # N = 0 (a bound is a few ticks; small programs are cheap), then bisect the last doubling
    lo, hi, best = -1, 0, None
    while (best := _feasible(impulse, hi, hold, step_rad_s, tol, voltage_limit_v)) is None:
        if hi >= n_max:
            raise InputError(f"no admissible voltage settles this step within {max_s:g} s")
        lo, hi = hi, min(n_max, 2 * hi + 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        u = _feasible(impulse, mid, hold, step_rad_s, tol, voltage_limit_v)
        if u is None:
            lo = mid
        else:
            hi, best = mid, u
    best = _closest(impulse, hi, hold, step_rad_s, tol, voltage_limit_v, best)
    speed = plant.simulate(best)
    best.setflags(write=False)
    speed.setflags(write=False)
    return SettlingBound(hi * ts, hi, best, speed, plant.nk - 1, tol)


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
