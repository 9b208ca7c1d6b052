"""One designed controller against N ARX plants at once (``tune --robust``): one Python loop over
the ticks, each quantity an array over the plants.

Each tick does, operation for operation, what a tick of ``cartctl run --fast`` does with one
motor of an ``ArxPlant`` without noise: the runtime's own laws on arrays (``pi_law`` or
``feedback_law``, the fixed-gain estimator's ``filter_correct``/``filter_predict`` around it),
the loop's clamp, the plant's saturation and ``arx_next`` with every plant's input coefficients
laid out by lag (so plants of different delays run together). A plant past ``DIVERGED_RAD_S``
is marked as run away and held at zero. ``tests/test_control_laws.py`` checks the traces against
the real loop bit for bit."""

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

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ArxBatch:
    """N ARX plants of one motor: ``ar`` (N, na) and ``b_lags`` (N, L), the coefficient of u[k − l]
    in y[k + 1] (b_i at l = nk − 1 + i, else 0; rad/s per V), with the plants' saturation (V) and Ts
    (s)."""

    ar: FloatArray
    b_lags: FloatArray
    voltage_limit_v: float = SUPPLY_V
    period_s: float = PERIOD_S

    @property
    def size(self) -> int:
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
        """From ``ar`` (N, na), ``b`` (N, nb) and input delays ``nk`` (N,) ≥ 1."""
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
    """One motor's traces over N plants, as ``cartctl run`` logs them (n ticks, then the stop row).

    ``time_s`` and ``reference`` (n + 1,) in s and rad/s; ``speed`` (N, n + 1), the measured and
    true speed (rad/s); ``voltage`` (N, n + 1), the command sent (V, 0 in the stop row);
    ``diverged`` (N,), the plants that ran away."""

    time_s: FloatArray
    reference: FloatArray
    speed: FloatArray
    voltage: FloatArray
    diverged: NDArray[np.bool_]


def _filter_terms(est: object) -> FilterTerms:
    if isinstance(est, SteadyStateSpeedEstimator):
        return est.terms
    raise InputError(
        f"the batch loop runs the fixed-gain estimator only, not {type(est).__name__} (a design "
        "with timing noise, timing_noise_std_ticks > 0, has a gain that depends on the commands)"
    )


class _PiBatch:
    """:class:`PiController`'s :func:`~cartctl.runtime.pi.pi_law` over N rows."""

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
    """:class:`StateFeedbackController`'s :func:`~cartctl.runtime.statefeedback.feedback_law` over N
    rows."""

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


def simulate_batch(
    controller: Controller,
    plants: ArxBatch,
    reference: ArrayLike,
    *,
    voltage_limit_v: float = SUPPLY_V,
) -> BatchTrace:
    """Run ``controller``'s design (read only: gains, limit, anti-windup, estimator) against every
    plant from rest, with the loop's clamp ``voltage_limit_v`` (V), following ``reference`` (rad/s,
    one value per tick)."""
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
