"""A truer speed for a recorded trace: a Kalman filter forward over the whole trace (filterpy),
then its RTS smoother back, so every tick's estimate uses the whole trace.

The state is the design's estimator's (:func:`~cartctl.design.kalman.design_kalman`, with its
process noise) plus two: θ, the counted angle (rad), θ[k+1] = θ[k] + Ts x_1[k+1], measured with
R = Δ²/12 (the summed encoder speeds are a floored true angle, Δ = 2π/1792 rad: white, where a
speed's error is correlated between neighbours); and a constant 1 through which the voltage enters
each tick's transition, F[k] = [[A, B u[k]], …] (``rts_smoother`` has no input term; its variance
is 0, so the smoother inverts with the pseudo-inverse). Row k holds the voltage commanded and the
speed measured at tick k; the speed at tick k is the mean of x̂_1[k] and x̂_1[k+1], the last row
using the model's prediction.
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

METHOD = "kalman-rts"  # how the JSON summaries name the smoothed speed


def angle_noise_std_rad(counts_per_rev: int = ENCODER_COUNTS_PER_REV) -> float:
    """Std (rad) of a counted angle: Δ/√12, one count Δ = 2π/counts_per_rev."""
    return 2.0 * math.pi / counts_per_rev / math.sqrt(12.0)


@dataclass(frozen=True, eq=False)
class SmoothedSpeed:
    """The smoothed speed of one motor per row: at the row's tick (rad/s, comparable with a
    simulator's ``true_speed``), the mean over the last tick (what the encoder measures, comparable
    with ``speed``), and the input disturbance (V)."""

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
    """The RTS-smoothed speed of one motor from the voltage (V) and encoder speed (rad/s) of each
    row, the noise levels as :func:`~cartctl.design.kalman.design_kalman` takes them; InputError
    for arrays of different lengths or with non-finite values, nk = 0, a noise level out of range.
    """
    u = _finite("the voltage", voltage_v)
    y = _finite("the speed", speed_rad_s)
    if u.size != y.size:
        raise InputError(f"voltage and speed differ in length: {u.size} and {y.size} rows")
    design = design_kalman(
        model,
        process_noise_std_v=process_noise_std_v,
        bias_drift_std_v=bias_drift_std_v,
        counts_per_rev=counts_per_rev,
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
