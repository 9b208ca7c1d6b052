"""Closed-loop simulations of a design, its margins, and the physical limit its step is
measured against.

The runtime controller (estimator, anti-windup and limit included) runs against the model
saturated at the supply, in the tick order of :mod:`cartctl.runtime.base`: a reference step, and a
load step d at the plant input, v[k] = u[k − extra] + d (a serial link delays the command, not the
load). Margins and Ms of L = C_fb·G·z^(−extra) are python-control's (:func:`loop_analysis`).

The limit (:func:`settling_bound`): y = T u for a step from rest (T the Toeplitz matrix of the
impulse response), so settling from tick N is a linear feasibility problem, |u[k]| ≤ U_max and
|y[k] − r| ≤ max(0.02 |r|, q) for N ≤ k < N + M (q one encoder count per tick). The smallest
feasible N (HiGHS linear programs, bisected) is the bound no controller beats; a step's settling
time, measured in the same band (:func:`in_settling_band`), is reported as a ratio to it.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import SUPPLY_V, encoder_quantum_rad_s
from cartctl.errors import InputError
from cartctl.measures.stepinfo import (
    SETTLING_FRACTION,
    StepInfo,
    settling_half_width,
    step_info,
)
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.base import Controller

RECOVERY_FRACTION = 0.02  # a disturbance is recovered once within this fraction of its peak
DEFAULT_DISTURBANCE_V = 1.0  # the load step at the plant input (V)


@dataclass(frozen=True)
class StepAnalysis:
    """A simulated closed-loop step, per tick: time (s), reference, modelled speed, the speed
    the controller acted on (rad/s) and the command (V); ``info`` its metrics."""

    time_s: NDArray[np.float64]
    reference_rad_s: NDArray[np.float64]
    speed_rad_s: NDArray[np.float64]
    estimate_rad_s: NDArray[np.float64]
    voltage_v: NDArray[np.float64]
    info: StepInfo

    @property
    def peak_voltage_v(self) -> float:
        return float(np.max(np.abs(self.voltage_v)))

    def to_dict(self) -> dict[str, Any]:
        """``design --json``'s ``step`` entry."""
        info = self.info.to_dict()
        keys = ("overshoot_percent", "settling_time_s", "rise_time_s", "steady_state_error")
        return {
            **{k: info[k] for k in keys},
            "peak_voltage_v": self.peak_voltage_v,
            "step_rad_s": float(self.reference_rad_s[-1]),
        }


def _run(
    controller: Controller,
    plant_model: ArxModel,
    duration_s: float,
    reference: float,
    disturbance_v: float,
    command_delay_ticks: int,
) -> tuple[NDArray[np.float64], ...]:
    """(time, speed, estimate, voltage) of the loop, from rest, the controller reset first."""
    plant = ArxPlant(plant_model, plant_model)
    n = max(2, round(duration_s / plant_model.period_s))
    speed, estimate, voltage = np.zeros(n), np.zeros(n), np.zeros(n)
    queue: deque[float] = deque([0.0] * int(command_delay_ticks))
    controller.reset()
    y = plant.reset().speed_a_rad_s
    for k in range(n):
        u = controller.step(reference, y)
        speed[k], estimate[k], voltage[k] = y, controller.estimate_rad_s, u
        queue.append(u)
        y = plant.step(queue.popleft() + disturbance_v, 0.0).speed_a_rad_s
    return np.arange(n, dtype=np.float64) * plant_model.period_s, speed, estimate, voltage


def simulate_step(
    controller: Controller,
    model: ArxModel,
    *,
    step_rad_s: float = 10.0,
    duration_s: float = 2.0,
    extra_delay_ticks: int = 0,
) -> StepAnalysis:
    """Step the reference from 0 to ``step_rad_s`` (rad/s) at t = 0 and run the closed loop for
    ``duration_s`` on the model with ``extra_delay_ticks`` more ticks of input delay."""
    plant_model = model.with_extra_delay(extra_delay_ticks)
    r = float(step_rad_s)
    time_s, speed, estimate, voltage = _run(controller, plant_model, duration_s, r, 0.0, 0)
    info = step_info(time_s, speed, reference=r, initial=0.0, onset_s=0.0)
    return StepAnalysis(time_s, np.full(time_s.size, r), speed, estimate, voltage, info)


@dataclass(frozen=True, eq=False)
class DisturbanceResponse:
    """A simulated load-disturbance step: from t = 0 (``time_s``, s) the speed deviation y from
    the reference 0 (``speed_rad_s``), the command u (``voltage_v``; it settles at −d when the
    controller rejects the load) and the step d (``disturbance_v``, V)."""

    time_s: NDArray[np.float64]
    speed_rad_s: NDArray[np.float64]
    voltage_v: NDArray[np.float64]
    disturbance_v: float

    @property
    def peak_index(self) -> int:
        return int(np.argmax(np.abs(self.speed_rad_s)))

    @property
    def peak_deviation_rad_s(self) -> float:
        """The deviation of largest magnitude, with its sign (rad/s)."""
        return float(self.speed_rad_s[self.peak_index])

    @property
    def recovery_band_rad_s(self) -> float:
        return RECOVERY_FRACTION * abs(self.peak_deviation_rad_s)

    @property
    def recovery_time_s(self) -> float | None:
        """First time after the peak from which |y| stays within the band (s); None if never."""
        outside = np.flatnonzero(np.abs(self.speed_rad_s) > self.recovery_band_rad_s)
        if outside.size == 0 or outside[-1] == self.speed_rad_s.size - 1:
            return None
        return float(self.time_s[outside[-1] + 1])

    def to_dict(self) -> dict[str, Any]:
        """The ``disturbance`` entry of ``design --json``."""
        return {
            "step_v": self.disturbance_v,
            "peak_deviation_rad_s": self.peak_deviation_rad_s,
            "peak_time_s": float(self.time_s[self.peak_index]),
            "recovery_time_s": self.recovery_time_s,
            "recovery_band_rad_s": self.recovery_band_rad_s,
            "final_deviation_rad_s": float(self.speed_rad_s[-1]),
            "final_voltage_v": float(self.voltage_v[-1]),
        }


def simulate_disturbance(
    controller: Controller,
    model: ArxModel,
    *,
    disturbance_v: float = DEFAULT_DISTURBANCE_V,
    duration_s: float = 2.0,
    extra_delay_ticks: int = 0,
) -> DisturbanceResponse:
    """Add ``disturbance_v`` (V) at the plant input from t = 0 and run the loop with r = 0 for
    ``duration_s``, the command (not the load) delayed by ``extra_delay_ticks``."""
    d = float(disturbance_v)
    time_s, speed, _, voltage = _run(controller, model, duration_s, 0.0, d, extra_delay_ticks)
    return DisturbanceResponse(time_s, speed, voltage, d)


def settling_band_rad_s(
    step_rad_s: float,
    period_s: float,
    *,
    fraction: float = SETTLING_FRACTION,
    quantum_rad_s: float | None = None,
) -> float:
    """Half-width (rad/s) of the settling band of a step r: max(fraction · |r|, q), q by default
    one encoder count per tick (a narrower band would judge the encoder, not the controller).
    InputError for a zero or non-finite step, or a step inside its own band.
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
    """The same simulated step with its metrics measured in the band of
    :func:`settling_band_rad_s`, as :func:`settling_bound` is (only the settling time changes)."""
    r = float(step.reference_rad_s[-1])
    settling_band_rad_s(r, period_s)  # refuses a step inside its own band, as the bound does
    info = step_info(step.time_s, step.speed_rad_s, reference=r, initial=0.0,
                     onset_s=float(step.time_s[0]), settling_floor=encoder_quantum_rad_s(period_s))  # fmt: skip
    return replace(step, info=info)


@dataclass(frozen=True)
class SettlingBound:
    """The time-optimal settling bound of a step: the smallest time (s, and ticks) from which
    the output can stay in the band, a voltage sequence achieving it and the response to it."""

    settling_time_s: float
    ticks: int
    voltage_v: NDArray[np.float64]
    speed_rad_s: NDArray[np.float64]
    loop_delay_ticks: int
    band_rad_s: float


def _feasible(
    impulse: NDArray[np.float64],
    n_settle: int,
    hold: int,
    r: float,
    band: float,
    u_max: float,
    closest: bool = False,
) -> NDArray[np.float64] | None:
    """A voltage sequence (|u| ≤ u_max) whose output is within r ± band for ``hold`` ticks from
    tick N = ``n_settle``, or None; with ``closest``, the one with the least Σ|y − r| after N
    (variables [u (n), t (M)]: minimise Σ t subject to −t ≤ y − r ≤ t and the band)."""
    from scipy import optimize
    from scipy.linalg import toeplitz

    n = n_settle + hold
    t = toeplitz(impulse[:n], np.zeros(n))[n_settle:]  # rows: y[k] for k in [N, N + M)
    a_ub = np.vstack([t, -t])
    b_ub = np.concatenate([np.full(hold, r + band), np.full(hold, -(r - band))])
    cost = np.zeros(n)
    bounds: list[tuple[float, float | None]] = [(-u_max, u_max)] * n
    if closest:
        eye, zeros = np.eye(hold), np.zeros((hold, hold))
        a_ub = np.block([[t, -eye], [-t, -eye], [t, zeros], [-t, zeros]])
        b_ub = np.concatenate([np.full(hold, r), np.full(hold, -r), b_ub])
        cost = np.concatenate([cost, np.ones(hold)])
        bounds += [(0.0, None)] * hold
    res = optimize.linprog(cost, A_ub=a_ub, b_ub=b_ub, bounds=bounds, method="highs")
    return res.x[:n] if res.status == 0 else None


@functools.lru_cache(maxsize=256)
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
    """Fastest settling of a step from rest to ``step_rad_s`` that any voltage within
    ±``voltage_limit_v`` allows, on the model with ``extra_delay_ticks`` more input delay, in the
    band max(``band`` · |r|, ``quantum_rad_s``), held for ``hold_s``, searched up to ``max_s``;
    cached (design, tune and commission ask for the same bound many times), so its arrays are
    read-only. InputError for a step that cannot be held within the limit (|r| − band above the
    DC gain × limit) or lies within its own band, a bad extra delay, or an unstable model.
    """
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
    clean = _feasible(impulse, hi, hold, step_rad_s, tol, voltage_limit_v, closest=True)
    best = best if clean is None else clean  # of those settling at N, the clean trace
    speed = plant.simulate(best)
    best.setflags(write=False)
    speed.setflags(write=False)
    return SettlingBound(hi * ts, hi, best, speed, plant.nk - 1, tol)


def loop_analysis(
    num: NDArray[np.float64], den: NDArray[np.float64], model: ArxModel, extra_delay_ticks: int
) -> dict[str, Any]:
    """``phase_margin_deg``, ``gain_margin_db`` (None when infinite), ``crossover_hz`` and
    ``sensitivity_peak`` Ms = max|1/(1 + L)| (1/sm, the shortest distance from L to −1; with its
    dB and Hz) of L = C G z^(−extra), C = ``num``/``den`` (descending powers of z), from one call
    of python-control's ``stability_margins``.

    The exact polynomial method is asked for (``margin``'s default grid misses the crossover of
    some well-damped designs), and each crossing it finds is checked on L itself (|L| = 1 within
    1e-6, a phase of −180° within 1e-4 rad: high-order loops give spurious roots) before
    python-control's choice (the smallest |PM|, the GM closest to 1).
    """
    import control

    ts = model.period_s
    delay = control.tf([1.0], [1.0] + [0.0] * extra_delay_ticks, ts)
    loop = control.tf(num, den, ts) * model.to_tf() * delay
    ln, ld = np.squeeze(loop.num[0][0]), np.squeeze(loop.den[0][0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        gms, pms, sms, w180, wcs, wms = control.stability_margins(
            loop, method="poly", returnall=True
        )

    def at(w: float) -> complex:
        z = np.exp(1j * w * ts)
        with np.errstate(divide="ignore", invalid="ignore"):
            return complex(np.polyval(ln, z) / np.polyval(ld, z))

    gain = [
        (g, w)
        for g, w in zip(np.atleast_1d(gms), np.atleast_1d(w180), strict=True)
        if w > 0.0
        and np.isfinite(at(w))
        and at(w).real < 0.0
        and abs(math.atan2(at(w).imag, -at(w).real)) < 1e-4
    ]
    phase = [
        (p, w)
        for p, w in zip(np.atleast_1d(pms), np.atleast_1d(wcs), strict=True)
        if np.isfinite(at(w)) and abs(abs(at(w)) - 1.0) < 1e-6
    ]
    gm = min(gain, key=lambda gw: abs(math.log(gw[0])))[0] if gain else math.inf
    pm, wcp = min(phase, key=lambda pw: abs(pw[0])) if phase else (math.inf, math.nan)
    ms = 1.0 / float(np.min(sms))
    # python-control searches ωTs in [0, 2π]: a peak above Nyquist is the mirror of one below
    wdt = float(wms[np.argmin(sms)]) * ts % (2.0 * math.pi)
    return {
        "sensitivity_peak": ms,
        "sensitivity_peak_db": 20.0 * math.log10(ms),
        "sensitivity_peak_hz": min(wdt, 2.0 * math.pi - wdt) / (2.0 * math.pi * ts),
        "phase_margin_deg": float(pm) if math.isfinite(pm) else None,
        "gain_margin_db": 20.0 * math.log10(gm) if math.isfinite(gm) and gm > 0 else None,
        "crossover_hz": float(wcp) / (2.0 * math.pi) if math.isfinite(wcp) else None,
    }
