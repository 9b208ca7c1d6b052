"""One designed controller against many ARX plants at once: the closed loop vectorised over plants.

``cartctl tune --robust`` scores every design on a few hundred plants
(:mod:`cartctl.tune.uncertainty`). Running :func:`cartctl.runtime.fast.run_in_memory` once per
plant costs a Python loop per plant (a few ms per 2 s run; ``benchmarks/bench_tune.py`` measures
it); here one Python loop over the ticks steps all N plants together, each
quantity an array of shape (N,) (or (N, m) for an estimator state).

Per tick k it steps, for every plant, the runtime's own laws on arrays (one element per plant),
so it does what one tick of ``cartctl run --fast`` does with one motor of
:class:`~cartctl.plants.sim.ArxPlant` (no measurement noise), operation for operation:

1. the controller: :func:`~cartctl.runtime.pi.pi_law` (:class:`~cartctl.runtime.pi.PiController`)
   or :func:`~cartctl.runtime.statefeedback.feedback_law`
   (:class:`~cartctl.runtime.statefeedback.StateFeedbackController`), with the fixed-gain
   estimator's :func:`~cartctl.runtime.kalman.filter_correct` and
   :func:`~cartctl.runtime.kalman.filter_predict` around it;
2. the loop's clamp to its voltage limit, then the plant's saturation at its own limit;
3. the plant: :func:`~cartctl.plants.sim.arx_next`, with the input coefficients of every plant laid
   out by lag (zero where a plant's delay puts none), so plants of different delays run together;
4. a speed beyond :data:`~cartctl.plants.sim.DIVERGED_RAD_S` marks that plant as run away (where
   the real loop stops with a plant fault); its row is held at zero from then on.

The trace ends like a run's: after the n ticks, the stop row (0 V, the measurement of tick n);
``tests/test_control_laws.py`` checks the traces against the real loop bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.cart import PERIOD_S, SUPPLY_V, check_voltage_limit
from cartctl.errors import InputError
from cartctl.model import ArxModel
from cartctl.plants.sim import DIVERGED_RAD_S, arx_next
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import (
    FilterTerms,
    SteadyStateSpeedEstimator,
    filter_correct,
    filter_predict,
)
from cartctl.runtime.pi import ANTI_WINDUP, PiController, pi_law
from cartctl.runtime.statefeedback import StateFeedbackController, feedback_law

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


# -- controllers: the runtime's laws on arrays ----------------------------------------------------


def _filter_terms(est: object) -> FilterTerms:
    if isinstance(est, SteadyStateSpeedEstimator):
        return est.terms
    raise InputError(
        f"the batch loop runs the fixed-gain estimator only, not {type(est).__name__} (a design "
        "with timing noise, timing_noise_std_ticks > 0, has a gain that depends on the commands)"
    )


class _PiBatch:
    """:class:`PiController` over N rows: its :func:`~cartctl.runtime.pi.pi_law` on arrays."""

    def __init__(self, ctrl: PiController, n: int) -> None:
        self.gains = (ctrl.kp, ctrl.ki * ctrl.period_s, ctrl.tracking_gain_per_tick,
                      ANTI_WINDUP.index(ctrl.anti_windup), ctrl.voltage_limit_v)  # fmt: skip
        self.integral: FloatArray = np.zeros(n)
        self.est = None if ctrl.estimator is None else _filter_terms(ctrl.estimator)
        self.x: list[FloatArray] = [np.zeros(n) for _ in (self.est.L if self.est else ())]

    def step(self, r: float, y: FloatArray) -> FloatArray:
        if self.est is not None:
            self.x = filter_correct(self.est, self.x, y)
            y = self.x[0]
        u, self.integral = pi_law(r - y, self.integral, *self.gains)
        if self.est is not None:
            self.x = filter_predict(self.est, self.x, u)
        return u


class _FeedbackBatch:
    """:class:`StateFeedbackController` over N rows: its
    :func:`~cartctl.runtime.statefeedback.feedback_law` on arrays (finite inputs)."""

    def __init__(self, ctrl: StateFeedbackController, n: int) -> None:
        self.ctrl = ctrl
        self.integral: FloatArray = np.zeros(n)
        self.est = _filter_terms(ctrl.estimator)
        self.x: list[FloatArray] = [np.zeros(n) for _ in self.est.L]

    def step(self, r: float, y: FloatArray) -> FloatArray:
        self.x = filter_correct(self.est, self.x, y)
        u_raw, u, self.integral = feedback_law(r, y, self.x, self.integral, self.ctrl.terms,
                                               self.ctrl.voltage_limit_v)  # fmt: skip
        u = np.where(np.isfinite(u_raw), u, 0.0)
        self.x = filter_predict(self.est, self.x, u)
        return u


def _controller(ctrl: Controller, n: int) -> _PiBatch | _FeedbackBatch:
    if isinstance(ctrl, PiController):
        return _PiBatch(ctrl, n)
    if isinstance(ctrl, StateFeedbackController):
        return _FeedbackBatch(ctrl, n)
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
    ctrl = _controller(controller, n)
    na, width = plants.ar.shape[1], plants.b_lags.shape[1]
    ar, b_lags = list(plants.ar.T), list(plants.b_lags.T)
    # row width − 1 + k of u_hist is u[k] as the plant applies it, row na + k of y_hist is y[k]
    # (one column per plant), zeros before tick 0 (rest); voltage[:, k] is u[k] as sent and logged
    u_hist = np.zeros((width - 1 + n_ticks, n))
    y_hist = np.zeros((na + n_ticks + 1, n))
    voltage = np.zeros((n, n_ticks + 1))
    diverged = np.zeros(n, dtype=bool)
    loop_lim, plant_lim = float(voltage_limit_v), plants.voltage_limit_v
    with np.errstate(all="ignore"):
        for k in range(n_ticks):
            u = ctrl.step(float(ref[k]), y_hist[na + k])
            u = np.minimum(loop_lim, np.maximum(-loop_lim, np.where(np.isfinite(u), u, 0.0)))
            voltage[:, k] = u
            base = width - 1 + k
            u_hist[base] = np.minimum(plant_lim, np.maximum(-plant_lim, u))
            y_next = arx_next(b_lags, u_hist[base::-1], 0, ar, y_hist[na + k :: -1])
            diverged |= ~(np.abs(y_next) < DIVERGED_RAD_S)
            y_next[diverged] = 0.0
            y_hist[na + k + 1] = y_next
    period = plants.period_s
    time_s = np.arange(n_ticks + 1, dtype=np.float64) * period
    time_s[-1] = time_s[-2] + period  # the stop row: the last tick's time + Ts, as the loop logs it
    return BatchTrace(time_s, np.append(ref, ref[-1]), np.ascontiguousarray(y_hist[na:].T),
                      voltage, diverged)  # fmt: skip
