"""A truer speed for a recorded trace: a Kalman filter over the whole trace, then an RTS smoother.

Where it sits: beside the estimator it reuses (:mod:`cartctl.design.kalman`), applied after a
run to its trace (``run``'s summary, ``review``). A real cart gives only its encoder speed, a whole
number of counts per tick (q = 2π/1792/Ts = 0.35 rad/s at 10 ms), so a step's overshoot and
settling are blurred by a count. With the motor model and the voltages that were sent, the speed
between the counts is well determined: filterpy's ``KalmanFilter`` runs forward over the trace and
its ``rts_smoother`` runs back, so every tick's estimate uses the whole trace. Pure numerics:
arrays in, arrays out.

The model. The state is that of the Kalman estimator the design stage builds
(:func:`cartctl.design.kalman.design_kalman` on the observer-form realisation of the ARX model,
:mod:`cartctl.design.statespace`): the realisation's states x (x_1 = the modelled *measured*
speed, the mean over the last tick, rad/s) and the input disturbance b (V: friction, the model's
DC error). Two states are added here:

- θ, the wheel angle the encoder counted (rad): θ[k+1] = θ[k] + Ts x_1[k+1]. The encoder speeds
  summed, Ts Σ_{j≤k} speed[j], are exactly the counted angle, a floored true angle: an error
  uniform over one count Δ = 2π/1792 rad, variance R = Δ²/12, white as long as the wheel turns
  (its mean Δ/2 is a constant offset, which θ absorbs). That is the measurement. Measuring the
  speed itself instead would be the difference of two such errors: variance Δ²/6 per tick and
  neighbours correlated by −½, which a Kalman filter cannot take as white.
- a constant 1, through which the recorded voltage enters the transition of each tick:
  F[k] = [[A, B u[k]], …] so x[k+1] = A x[k] + B u[k]. filterpy's ``rts_smoother`` has no input
  term; with it inside F[k] the smoother is exact for a known input. Its variance is 0, so the
  predicted covariance is singular in that direction and the smoother inverts it with the
  pseudo-inverse (filterpy's ``inv`` argument).

The noise. The process noise is that of the design's estimator: an input-equivalent voltage
w with σ_w = ``process_noise_std_v`` (default 0.1 V: PWM rounding, the fast part of friction and
model error) and a random-walk bias with step σ_b = ``bias_drift_std_v`` (default 0.03 V per tick),
both entering where the voltage does; the angle shares x_1's noise. The measurement noise is the
quantisation alone (the model files record no noise level).

Rows and delays. Row k holds the voltage commanded at tick k and the speed measured at tick k
(the trace columns): the model applies to the rows as written, with its own nk. A loop slower
than the one the model was identified on (``extra_delay_ticks``, as in ``design``) adds whole
ticks of input delay.

The speed at a tick. x̂_1[k] estimates the mean speed over the last tick, about the true speed
half a tick earlier. The estimate of the true speed at tick k is the mean of x̂_1[k] and x̂_1[k+1]
(exact for a speed that changes linearly over the two ticks; the same as the design's
estimator, :mod:`cartctl.design.kalman`); the last row uses the model's prediction of x_1 one tick
on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter
from numpy.typing import ArrayLike, NDArray

from cartctl.cart import ENCODER_COUNTS_PER_REV
from cartctl.design.kalman import design_kalman
from cartctl.design.request import DEFAULT_BIAS_DRIFT_STD_V, DEFAULT_PROCESS_NOISE_STD_V
from cartctl.errors import InputError
from cartctl.model import ArxModel

__all__ = ["METHOD", "SmoothedSpeed", "angle_noise_std_rad", "smooth_speed"]

METHOD = "kalman-rts"
"""How the smoothed speed is made, as the JSON summaries name it."""


def angle_noise_std_rad(counts_per_rev: int = ENCODER_COUNTS_PER_REV) -> float:
    """Standard deviation (rad) of a counted angle: one count Δ = 2π/counts_per_rev, Δ/√12."""
    return 2.0 * math.pi / counts_per_rev / math.sqrt(12.0)


@dataclass(frozen=True, eq=False)
class SmoothedSpeed:
    """The smoothed speed of one motor over a trace.

    Attributes
    ----------
    speed_rad_s : ndarray, shape (N,)
        The estimate of the true speed at each row's tick (rad/s): comparable with a simulator's
        ``true_speed``.
    mean_speed_rad_s : ndarray, shape (N,)
        The estimate of what the encoder measures at each row, the mean speed over the last tick
        (rad/s): comparable with ``speed``.
    bias_v : ndarray, shape (N,)
        The estimated input disturbance (V).
    """

    speed_rad_s: NDArray[np.float64]
    mean_speed_rad_s: NDArray[np.float64]
    bias_v: NDArray[np.float64]


def _finite(name: str, values: ArrayLike) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=float).ravel()
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise InputError(f"{name} is not finite at row {int(bad[0])} ({array[bad[0]]})")
    return array


def smooth_speed(
    model: ArxModel,
    voltage_v: ArrayLike,
    speed_rad_s: ArrayLike,
    *,
    extra_delay_ticks: int = 0,
    process_noise_std_v: float = DEFAULT_PROCESS_NOISE_STD_V,
    bias_drift_std_v: float = DEFAULT_BIAS_DRIFT_STD_V,
    counts_per_rev: int = ENCODER_COUNTS_PER_REV,
) -> SmoothedSpeed:
    """The RTS-smoothed speed of one motor (see the module docstring for the model).

    Parameters
    ----------
    model : ArxModel
        The motor's model, voltage (V) to measured speed (rad/s), nk >= 1.
    voltage_v : array_like, shape (N,)
        The voltage commanded at each row (V).
    speed_rad_s : array_like, shape (N,)
        The encoder speed measured at each row (rad/s), a whole number of counts per tick.
    extra_delay_ticks : int
        Ticks of loop delay beyond the one the model was identified on (>= 0).
    process_noise_std_v : float
        σ_w, the white input-equivalent voltage noise (V), > 0.
    bias_drift_std_v : float
        σ_b, the step of the input disturbance's random walk (V per tick), >= 0 (0: no bias state).
    counts_per_rev : int
        Encoder counts per wheel revolution (sets the angle's quantisation).

    Returns
    -------
    SmoothedSpeed

    Raises
    ------
    InputError
        Arrays of different lengths or with non-finite values; a model with nk = 0; a noise level
        out of range.
    """
    u = _finite("the voltage", voltage_v)
    y = _finite("the speed", speed_rad_s)
    if u.size != y.size:
        raise InputError(f"voltage and speed differ in length: {u.size} and {y.size} rows")
    if not isinstance(counts_per_rev, int | np.integer) or counts_per_rev < 1:
        raise InputError(f"counts_per_rev must be a whole number >= 1, got {counts_per_rev!r}")
    design = design_kalman(
        model,
        process_noise_std_v=process_noise_std_v,
        bias_drift_std_v=bias_drift_std_v,
        counts_per_rev=int(counts_per_rev),
        extra_delay_ticks=extra_delay_ticks,
    )
    n_rows = u.size
    if n_rows == 0:
        empty = np.empty(0)
        return SmoothedSpeed(empty, empty.copy(), empty.copy())
    ts = model.period_s
    A, B, C = design.A, design.B, design.C
    m = A.shape[0]
    angle, one = m, m + 1  # the indexes of the two added states
    F0 = np.zeros((m + 2, m + 2))
    F0[:m, :m] = A
    F0[angle, :m] = ts * (C @ A)
    F0[angle, angle] = 1.0
    F0[one, one] = 1.0
    drive = np.zeros(m + 2)  # the column of the constant: where u[k] enters
    drive[:m] = B
    drive[angle] = ts * float(C @ B)
    Fs = np.repeat(F0[np.newaxis], n_rows, axis=0)
    Fs[:, :, one] += u[:, np.newaxis] * drive
    to_aug = np.vstack([np.eye(m), ts * C, np.zeros(m)])  # the design's noise, into x, θ
    Q = to_aug @ design.Q @ to_aug.T

    kf = KalmanFilter(dim_x=m + 2, dim_z=1)
    kf.H = np.zeros((1, m + 2))
    kf.H[0, angle] = 1.0
    kf.R = np.array([[angle_noise_std_rad(int(counts_per_rev)) ** 2]])
    kf.Q = Q
    angle_rad = ts * np.cumsum(y)  # the counted angle, since the trace's first row
    kf.x = np.zeros(m + 2)
    kf.x[angle] = angle_rad[0]
    kf.x[one] = 1.0
    P0 = np.zeros((m + 2, m + 2))
    P0[:m, :m] = design.P + np.eye(m) * max(y[0] ** 2, design.R)  # the trace may start moving
    P0[angle, angle] = float(kf.R[0, 0]) + (ts * design.measurement_noise_std_rad_s) ** 2
    kf.P = P0
    means, covariances, _, _ = kf.batch_filter(angle_rad, Fs=list(Fs), Qs=[Q] * n_rows,
                                               update_first=True)  # fmt: skip
    # rts_smoother takes Fs[k + 1] as the step k → k + 1; with update first that is F[k]
    shifted = [F0, *Fs[:-1]]
    x, _, _, _ = kf.rts_smoother(means, covariances, Fs=shifted, Qs=[Q] * n_rows,
                                 inv=np.linalg.pinv)  # fmt: skip
    mean_speed = np.array(x[:, 0], dtype=float)
    after_last = float((Fs[-1] @ x[-1])[0])
    following = np.append(mean_speed[1:], after_last)
    bias = np.array(x[:, m - 1], dtype=float) if design.has_bias else np.zeros(n_rows)
    return SmoothedSpeed(0.5 * (mean_speed + following), mean_speed, bias)
