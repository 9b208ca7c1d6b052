"""The realisation of a motor model and the steady-state Kalman speed estimator designed on it.

The realisation is the observer canonical form of G(z) = (β_1 z^{n−1} + … + β_n) / (z^n + α_1
z^{n−1} + … + α_n) (β the numerator padded to n), a state with a meaning (the state fed back is
the state estimated; python-control's ``ss(tf)`` picks none)::

    x[k+1] = A x[k] + B u[k],   y[k] = C x[k],   A = [−α | I_{n−1}; 0],   B = β,   C = [1, 0, …, 0]

x_1[k] = y[k] is the modelled speed, x_j[k] (j ≥ 2) the part of y[k + j − 1] that inputs and
outputs up to k − 1 already fix (rad/s); for (a z + b) / (z³ + c z² + d z), x_2[k] = y[k+1] +
c y[k] and x_3[k] = b u[k−1].

The estimator's model is that realisation with the loop's whole delay as states (nk, plus
``extra_delay_ticks``: the prediction knows which voltages are on their way) and one
input-disturbance state b (V)::

    x[k+1] = A x[k] + B (u[k] + b[k] + w[k]),    b[k+1] = b[k] + w_b[k],    y[k] = x_1[k] + v[k]

w has std ``process_noise_std_v``; b, a random walk of step std ``bias_drift_std_v`` per tick (0
leaves it out), is dry friction and the model's DC error: the estimate is offset-free and b̂ is
pole placement's integral action; v is the encoder quantisation, R = q²/6 + (extra noise)², q one
count per tick. x̂_1[k|k] estimates the measured mean speed over the last tick; the speed at tick
k itself is (x̂_1[k|k] + x̂_1[k+1|k]) / 2.

The gain is the steady-state filter gain L = P Cᵀ (C P Cᵀ + R)⁻¹, P the a priori covariance of
the filter DARE (``control.dlqe`` gives the predictor gain A L instead): x̂[k|k] = x̂[k|k−1] +
L (y[k] − C x̂[k|k−1]), whose error evolves with (I − L C) A (the estimator poles).

:func:`smooth_speed` gives a recorded trace a truer speed: this filter forward over the whole
trace (filterpy), then its RTS smoother back. Its state adds two: θ, the counted angle (rad),
θ[k+1] = θ[k] + Ts x_1[k+1], measured with R = Δ²/12 (the summed encoder speeds are a floored
true angle, Δ = 2π/1792 rad: white, where a speed's error is correlated between neighbours); and
a constant 1 through which the voltage enters each tick's transition, F[k] = [[A, B u[k]], …]
(``rts_smoother`` has no input term; its variance is 0, so the smoother inverts with the
pseudo-inverse). The speed at row k's tick is the mean of x̂_1[k] and x̂_1[k+1].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.cart import ENCODER_COUNTS_PER_REV, encoder_quantum_rad_s
from cartctl.design.request import DEFAULT_BIAS_DRIFT_STD_V, DEFAULT_PROCESS_NOISE_STD_V
from cartctl.errors import InputError
from cartctl.model import ArxModel, check_extra_delay_ticks, check_input_delay
from cartctl.runtime.kalman import KalmanDesign as KalmanDesign  # re-exported: a design's result


@dataclass(frozen=True, eq=False)
class StateSpace:
    """A discrete SISO system ``x[k+1] = A x + B u``, ``y = C x`` (A (n, n), B (n,) in rad/s per
    V, C (n,)) with sample period Ts (s)."""

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    period_s: float

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    def to_control(self):
        """The system as a python-control ``StateSpace`` with dt = Ts."""
        import control

        n = self.order
        return control.ss(self.A, self.B.reshape(n, 1), self.C.reshape(1, n), 0.0, self.period_s)

    def simulate(self, voltage_v: NDArray[np.float64]) -> NDArray[np.float64]:
        """Output y[k] (rad/s) for the input u[k] (V), shape (N,), from x[0] = 0."""
        import control

        u = np.asarray(voltage_v, dtype=float)
        if u.size == 0:
            return np.empty(0)
        return np.asarray(control.forced_response(self.to_control(), U=u).outputs, dtype=float)

    def is_controllable(self) -> bool:
        """True when every mode can be moved by u (PBH test: rank [λI − A, B] = n for each λ)."""
        return not uncontrollable_modes(self.A, self.B)


def uncontrollable_modes(A: NDArray[np.float64], B: NDArray[np.float64]) -> list[complex]:
    """Eigenvalues of A (n, n) that u through B (n,) cannot move (PBH test)."""
    n = A.shape[0]
    bad: list[complex] = []
    scale = max(1.0, float(np.linalg.norm(A)), float(np.linalg.norm(B)))
    for lam in np.linalg.eigvals(A):
        pbh = np.hstack([lam * np.eye(n) - A, B.reshape(n, 1)])
        if np.linalg.svd(pbh, compute_uv=False)[-1] < 1e-9 * scale:  # rank lost
            bad.append(complex(lam))
    return bad


def realise(model: ArxModel, *, extra_delay_ticks: int = 0) -> StateSpace:
    """The observer canonical realisation of an ARX model (V → rad/s) with its input delay nk
    (≥ 1: u[k] is computed after y[k] is measured) plus ``extra_delay_ticks`` d ≥ 0, order
    max(na, nk + d + nb − 1) (``model.order + d`` for the report's structure); InputError for
    nk = 0 or a bad extra delay."""
    check_extra_delay_ticks(extra_delay_ticks, "extra_delay_ticks")
    check_input_delay(model.nk)
    delayed = model.with_extra_delay(extra_delay_ticks)
    den = delayed.den()  # [1, α_1 … α_n]
    num = delayed.num()  # degree n − nk < n: strictly proper
    n = den.size - 1
    beta = np.zeros(n)
    beta[n - num.size :] = num
    A = np.zeros((n, n))
    A[:, 0] = 0.0 - den[1:]  # "0.0 −" keeps −0.0 out of the matrix
    A[: n - 1, 1:] = np.eye(n - 1)
    return StateSpace(A, beta, np.eye(1, n).ravel(), model.period_s)


def quantisation_std_rad_s(period_s: float, counts_per_rev: int = ENCODER_COUNTS_PER_REV) -> float:
    """Std (rad/s) of a whole-count speed's quantisation error: q / √6, q one count per tick."""
    return encoder_quantum_rad_s(period_s, counts_per_rev) / math.sqrt(6.0)


def _nonnegative(name: str, value: float, *, positive: bool = False) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
        need = "> 0" if positive else ">= 0"
        raise InputError(f"{name} must be a finite number {need}, got {value}")
    return value


def design_kalman(
    plant: ArxModel | StateSpace,
    *,
    process_noise_std_v: float = DEFAULT_PROCESS_NOISE_STD_V,
    bias_drift_std_v: float = DEFAULT_BIAS_DRIFT_STD_V,
    extra_noise_std_rad_s: float = 0.0,
    counts_per_rev: int = ENCODER_COUNTS_PER_REV,
    extra_delay_ticks: int = 0,
    timing_noise_std_ticks: float = 0.0,
) -> KalmanDesign:
    """The steady-state Kalman filter (the module docstring) on a model, realised with
    ``extra_delay_ticks`` more input delay, or on a realisation (then with none).

    σ_w = ``process_noise_std_v`` (V, > 0), σ_b = ``bias_drift_std_v`` (V per tick; 0 leaves the
    disturbance state out), ``extra_noise_std_rad_s`` added in variance to the quantisation
    (``measurement_noise_std_rad_s`` is the total √R), σ_ε = ``timing_noise_std_ticks`` for the
    time-varying filter's Q[k] = Q + (σ_ε Δu[k])² B Bᵀ. InputError for a noise level negative,
    non-finite or zero where it must not be, a bad count, or no stabilising DARE solution.
    """
    if isinstance(plant, ArxModel):
        plant = realise(plant, extra_delay_ticks=extra_delay_ticks)
    elif extra_delay_ticks != 0:
        raise InputError("extra_delay_ticks applies to an ArxModel; realise the delay into it")
    sw = _nonnegative("process_noise_std_v", process_noise_std_v, positive=True)
    sb = _nonnegative("bias_drift_std_v", bias_drift_std_v)
    extra = _nonnegative("extra_noise_std_rad_s", extra_noise_std_rad_s)
    timing = _nonnegative("timing_noise_std_ticks", timing_noise_std_ticks)
    if not isinstance(counts_per_rev, int | np.integer) or counts_per_rev < 1:
        raise InputError(f"counts_per_rev must be a whole number >= 1, got {counts_per_rev!r}")
    R = quantisation_std_rad_s(plant.period_s, int(counts_per_rev)) ** 2 + extra**2
    n = plant.order
    m = n + (1 if sb > 0.0 else 0)
    A = np.zeros((m, m))
    A[:n, :n] = plant.A
    B, C = (np.r_[v, np.zeros(m - n)] for v in (plant.B, plant.C))
    Q = np.zeros((m, m))
    Q[:n, :n] = sw**2 * np.outer(plant.B, plant.B)
    if m > n:
        A[:n, n] = plant.B  # the disturbance enters where the voltage does
        A[n, n] = 1.0
        Q[n, n] = sb**2
    try:
        import scipy.linalg

        P = scipy.linalg.solve_discrete_are(A.T, C.reshape(m, 1), Q, np.array([[R]]))
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise InputError(f"no steady-state Kalman gain for this model and noise ({exc})") from None
    P = 0.5 * (P + P.T)
    L = P @ C / (C @ P @ C + R)
    for array in (A, B, C, Q, P, L):
        array.setflags(write=False)
    return KalmanDesign(
        A=A,
        B=B,
        C=C,
        Q=Q,
        R=float(R),
        P=P,
        L=L,
        n_model_states=n,
        period_s=plant.period_s,
        process_noise_std_v=sw,
        bias_drift_std_v=sb,
        measurement_noise_std_rad_s=math.sqrt(R),
        timing_noise_std_ticks=timing,
    )


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

    from filterpy.kalman import KalmanFilter

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
