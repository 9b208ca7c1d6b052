"""One designed controller against many ARX plants at once: the closed loop vectorised over plants.

``cartctl tune --robust`` scores every design on a few hundred plants
(:mod:`cartctl.tune.uncertainty`). Running :func:`cartctl.runtime.fast.run_in_memory` once per
plant costs a Python loop per plant (a few ms per 2 s run; ``benchmarks/bench_tune.py`` measures
it); here one Python loop over the ticks steps all N plants together, each
quantity an array of shape (N,) (or (N, m) for an estimator state).

Per tick k it does, for every plant, exactly what one tick of ``cartctl run --fast`` does with one
motor of :class:`~cartctl.plants.sim.ArxPlant` (no measurement noise), in the same order and with
the same floating-point operations where the runtime uses plain floats:

1. the controller's step on (r[k], y[k]), as :class:`~cartctl.runtime.pi.PiController` (its
   anti-windup modes, the clamp, the optional estimator) or
   :class:`~cartctl.runtime.statefeedback.StateFeedbackController` (conditional integration, the
   estimator predicting with the clamped voltage) runs it; the estimators as
   :class:`~cartctl.runtime.kalman.SteadyStateSpeedEstimator` (fixed gain);
2. the loop's clamp to its voltage limit, then the plant's saturation at its own limit;
3. the difference equation y[k+1] = Σ b_i u[k+1−nk−i] − Σ a_j y[k+1−j]: with the input
   coefficients of every plant laid out by lag (zero where a plant's delay puts none), so plants of
   different delays run together; a zero coefficient adds an exact zero;
4. a speed beyond :data:`~cartctl.plants.sim.DIVERGED_RAD_S` marks that plant as run away (where
   the real loop stops with a plant fault); its row is held at zero from then on.

The trace ends like a run's: after the n ticks, the stop row (0 V, the measurement of tick n);
``tests/test_tune_batch.py`` checks the traces against the real loop to 1e-9.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.cart import PERIOD_S, SUPPLY_V, check_voltage_limit
from cartctl.errors import InputError
from cartctl.model import ArxModel
from cartctl.plants.sim import DIVERGED_RAD_S
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.pi import ANTI_WINDUP, PiController
from cartctl.runtime.statefeedback import StateFeedbackController

__all__ = ["ArxBatch", "BatchTrace", "simulate_batch"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ArxBatch:
    """N ARX plants of one motor, as arrays.

    Attributes
    ----------
    ar : ndarray, shape (N, na)
        a_1 … a_na of each plant (zeros pad a shorter one: an exact no-op).
    b_lags : ndarray, shape (N, L)
        The coefficient of u[k − l] in y[k + 1], l = 0 … L − 1: b_i at l = nk − 1 + i, else 0 (V⁻¹
        rad/s).
    voltage_limit_v : float
        The plants' saturation (V), as :class:`~cartctl.plants.sim.ArxPlant`'s.
    period_s : float
        Ts (s).
    """

    ar: FloatArray
    b_lags: FloatArray
    voltage_limit_v: float = SUPPLY_V
    period_s: float = PERIOD_S

    @property
    def size(self) -> int:
        """N, the number of plants."""
        return int(self.b_lags.shape[0])

    @classmethod
    def from_arrays(
        cls,
        ar: ArrayLike,
        b: ArrayLike,
        nk: ArrayLike,
        *,
        voltage_limit_v: float = SUPPLY_V,
        period_s: float = PERIOD_S,
    ) -> ArxBatch:
        """From per-plant coefficients: ``ar`` (N, na), ``b`` (N, nb), input delays ``nk`` (N,), ≥ 1."""
        ar_arr = np.asarray(ar, dtype=float)
        b_arr = np.asarray(b, dtype=float)
        nk_arr = np.asarray(nk, dtype=int)
        n = b_arr.shape[0]
        if ar_arr.ndim != 2 or b_arr.ndim != 2 or nk_arr.shape != (n,) or ar_arr.shape[0] != n:
            raise InputError(
                f"plant arrays must be ar (N, na), b (N, nb), nk (N,); got {ar_arr.shape}, "
                f"{b_arr.shape}, {nk_arr.shape}"
            )
        if n and int(nk_arr.min()) < 1:
            raise InputError(f"a plant needs an input delay nk >= 1, got {int(nk_arr.min())}")
        nb = b_arr.shape[1]
        width = (int(nk_arr.max()) - 1 + nb) if n else nb
        lags = np.zeros((n, width))
        rows = np.arange(n)
        for i in range(nb):
            lags[rows, nk_arr - 1 + i] = b_arr[:, i]
        return cls(ar_arr, lags, float(voltage_limit_v), float(period_s))

    @classmethod
    def from_models(
        cls, models: Sequence[ArxModel], *, voltage_limit_v: float = SUPPLY_V
    ) -> ArxBatch:
        """From ARX models of equal orders and period (their delays may differ)."""
        if not models:
            raise InputError("a plant batch needs at least one model")
        if len({(m.na, m.nb, m.period_s) for m in models}) != 1:
            raise InputError("the models of a plant batch must share na, nb and the period")
        return cls.from_arrays([m.ar for m in models], [m.b for m in models],
                               [m.nk for m in models], voltage_limit_v=voltage_limit_v,
                               period_s=models[0].period_s)  # fmt: skip


@dataclass(frozen=True)
class BatchTrace:
    """The traces of one motor over N plants, rows as ``cartctl run`` logs them (with the stop row).

    Attributes
    ----------
    time_s : ndarray, shape (n + 1,)
        k·Ts for the n ticks, then the stop row's time (s).
    reference : ndarray, shape (n + 1,)
        r[k] (rad/s); the stop row repeats the last.
    speed : ndarray, shape (N, n + 1)
        y[k], the measurement of tick k, which on the ARX plant is also the true speed (rad/s).
    voltage : ndarray, shape (N, n + 1)
        u[k], the command sent at tick k (V); 0 in the stop row.
    diverged : ndarray of bool, shape (N,)
        The plant's speed left ±:data:`~cartctl.plants.sim.DIVERGED_RAD_S` (the real loop fails).
    """

    time_s: FloatArray
    reference: FloatArray
    speed: FloatArray
    voltage: FloatArray
    diverged: NDArray[np.bool_]


# -- estimators ----------------------------------------------------------------------------------


class _SteadyBatch:
    """:class:`SteadyStateSpeedEstimator` over N rows: same non-zero entries, same order."""

    def __init__(self, est: SteadyStateSpeedEstimator, n: int) -> None:
        d = est.design
        m = d.A.shape[0]
        self.L = [float(v) for v in d.L]
        self.C = [(j, float(c)) for j, c in enumerate(d.C) if c != 0.0]
        self.A = [[(j, float(a)) for j, a in enumerate(d.A[i]) if a != 0.0] for i in range(m)]
        self.B = [float(b) for b in d.B]
        self.x = np.zeros((n, m))

    def correct(self, y: FloatArray, k: int) -> FloatArray:
        x = self.x
        innovation = y.copy()
        for j, c in self.C:
            innovation -= c * x[:, j]
        for i, li in enumerate(self.L):
            x[:, i] += li * innovation
        return x[:, 0]

    def predict(self, u: FloatArray) -> None:
        x = self.x
        new = np.empty_like(x)
        for i, (row, b) in enumerate(zip(self.A, self.B, strict=True)):
            acc = np.zeros(x.shape[0])
            for j, a in row:
                acc += a * x[:, j]
            new[:, i] = acc + b * u
        self.x = new


def _estimator(est: object, n: int, ticks: int) -> _SteadyBatch | None:
    if est is None:
        return None
    if isinstance(est, SteadyStateSpeedEstimator):
        return _SteadyBatch(est, n)
    if isinstance(est, KalmanSpeedEstimator):  # its gains follow the commands it is given
        raise InputError(
            "the batch loop cannot run an estimator with timing noise "
            "(timing_noise_std_ticks > 0): its gain depends on the commands"
        )
    raise InputError(f"the batch loop does not know the estimator {type(est).__name__}")


# -- controllers ---------------------------------------------------------------------------------


class _PiBatch:
    """:meth:`PiController.step` over N rows."""

    def __init__(self, ctrl: PiController, n: int, ticks: int) -> None:
        self.kp = ctrl.kp
        self.ki_ts = ctrl.ki * ctrl.period_s
        if ctrl.tracking_gain is not None:
            self.kt = float(ctrl.tracking_gain)
        else:  # PiController's default: a tracking time constant equal to Kp/Ki
            self.kt = min(1.0, ctrl.period_s * ctrl.ki / ctrl.kp) if ctrl.kp > 0.0 else 1.0
        self.mode = ANTI_WINDUP.index(ctrl.anti_windup)
        self.lim = ctrl.voltage_limit_v
        self.integral = np.zeros(n)
        self.est = _estimator(ctrl.estimator, n, ticks)

    def step(self, r: float, y: FloatArray, k: int) -> FloatArray:
        lim = self.lim
        if self.est is not None:
            y = self.est.correct(y, k)
        e = r - y
        integral = self.integral + self.ki_ts * e
        p = self.kp * e
        u = p + integral
        finite = np.isfinite(u)
        u_sat = np.minimum(lim, np.maximum(-lim, u))
        clamped = u_sat != u
        if self.mode == 0:  # conditional: up to the limit, never further
            held = clamped & (e * u > 0.0)
            if held.any():
                old = self.integral
                edge = u_sat - p
                moved = np.where(e > 0.0, np.maximum(old, np.minimum(integral, edge)),
                                 np.minimum(old, np.maximum(integral, edge)))  # fmt: skip
                integral = np.where(held, moved, integral)
                u_sat = np.where(held, np.minimum(lim, np.maximum(-lim, p + integral)), u_sat)
        elif self.mode == 1:  # back-calculation
            integral = np.where(clamped, integral + self.kt * (u_sat - u), integral)
        self.integral = np.where(finite, integral, self.integral)
        u_sat = np.where(finite, u_sat, 0.0)
        if self.est is not None:
            self.est.predict(u_sat)
        return u_sat


class _FeedbackBatch:
    """:meth:`StateFeedbackController.step` over N rows (finite inputs)."""

    def __init__(self, ctrl: StateFeedbackController, n: int, ticks: int) -> None:
        d = ctrl.design
        self.K = [float(v) for v in d.K]
        self.Ki = float(d.K_xi)
        self.Kr = float(d.Kr)
        self.Ts = float(d.period_s)
        self.lim = ctrl.voltage_limit_v
        self.integral = np.zeros(n)
        est = _estimator(ctrl.estimator, n, ticks)
        assert est is not None  # the controller always has one
        self.est = est

    def step(self, r: float, y: FloatArray, k: int) -> FloatArray:
        est = self.est
        est.correct(y, k)
        x = est.x
        u_raw = self.Kr * r - self.Ki * self.integral
        for j, kj in enumerate(self.K):
            u_raw = u_raw - kj * x[:, j]
        lim = self.lim
        u = np.minimum(lim, np.maximum(-lim, u_raw))
        u = np.where(np.isfinite(u_raw), u, 0.0)
        saturated = u != u_raw
        error = r - y
        grow = ~saturated | ((u_raw > u) != (-self.Ki * error > 0.0))
        self.integral = np.where(grow, self.integral + self.Ts * error, self.integral)
        est.predict(u)
        return u


def _controller(ctrl: Controller, n: int, ticks: int) -> _PiBatch | _FeedbackBatch:
    if isinstance(ctrl, PiController):
        return _PiBatch(ctrl, n, ticks)
    if isinstance(ctrl, StateFeedbackController):
        return _FeedbackBatch(ctrl, n, ticks)
    raise InputError(f"the batch loop does not know the controller {type(ctrl).__name__}")


# -- the loop ------------------------------------------------------------------------------------


def simulate_batch(
    controller: Controller,
    plants: ArxBatch,
    reference: ArrayLike,
    *,
    voltage_limit_v: float = SUPPLY_V,
) -> BatchTrace:
    """Run ``controller``'s design against every plant of ``plants``, from rest, all at once.

    Parameters
    ----------
    controller : PiController or StateFeedbackController
        Read only (its gains, limit, anti-windup and estimator); its own state is not touched.
    plants : ArxBatch
        The N plants (one motor each).
    reference : array_like, shape (n,)
        r[k] (rad/s) for the n ticks.
    voltage_limit_v : float
        The loop's clamp (V), as ``run_in_memory``'s.

    Returns
    -------
    BatchTrace
        The N traces, with the stop row.
    """
    ref = np.asarray(reference, dtype=float)
    if ref.ndim != 1 or ref.size == 0:
        raise InputError(f"the reference must be a non-empty 1-D array, got shape {ref.shape}")
    check_voltage_limit(voltage_limit_v)
    n_ticks, n = ref.size, plants.size
    ctrl = _controller(controller, n, n_ticks)
    na, width = plants.ar.shape[1], plants.b_lags.shape[1]
    ar = [plants.ar[:, j] for j in range(na)]
    b_lags = [plants.b_lags[:, lag] for lag in range(width)]
    # u_hist[:, width - 1 + k] = u[k] as the plant applies it; y_hist[:, na + k] = y[k]; zeros
    # before tick 0 (rest). voltage[:, k] = u[k] as the loop sent (and logged) it.
    u_hist = np.zeros((n, width - 1 + n_ticks))
    y_hist = np.zeros((n, na + n_ticks + 1))
    voltage = np.zeros((n, n_ticks + 1))
    diverged = np.zeros(n, dtype=bool)
    loop_lim, plant_lim = float(voltage_limit_v), plants.voltage_limit_v
    with np.errstate(all="ignore"):
        for k in range(n_ticks):
            u = ctrl.step(float(ref[k]), y_hist[:, na + k], k)
            u = np.minimum(loop_lim, np.maximum(-loop_lim, np.where(np.isfinite(u), u, 0.0)))
            voltage[:, k] = u
            base = width - 1 + k
            u_hist[:, base] = np.minimum(plant_lim, np.maximum(-plant_lim, u))
            y_next = np.zeros(n)
            for lag, b in enumerate(b_lags):
                y_next += b * u_hist[:, base - lag]
            for j, a in enumerate(ar):
                y_next -= a * y_hist[:, na + k - j]
            diverged |= ~(np.abs(y_next) < DIVERGED_RAD_S)
            y_next[diverged] = 0.0
            y_hist[:, na + k + 1] = y_next
    period = plants.period_s
    time_s = np.arange(n_ticks + 1, dtype=np.float64) * period
    time_s[-1] = time_s[-2] + period  # the stop row: the last tick's time + Ts, as the loop logs it
    return BatchTrace(time_s, np.append(ref, ref[-1]), y_hist[:, na:], voltage, diverged)
