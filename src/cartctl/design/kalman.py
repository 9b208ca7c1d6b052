"""The steady-state Kalman speed estimator, designed on the realisation of a motor model.

Where it sits: the ``design`` stage, beside pole placement (which embeds one in every
:class:`~cartctl.design.poles.PolesDesign`) and the PI (``--estimator kalman``). The runtime
estimators in :mod:`cartctl.runtime.kalman` run what is designed here.

The estimator's model is the observer-form realisation of :mod:`cartctl.design.statespace`
(x_1 = the modelled speed) with the loop's true delay in it: the model's nk (the report's 2: one
tick of loop delay on board and in the simulators) plus ``extra_delay_ticks`` (3 through the PC
serial loop), realised as states, so the prediction knows which voltages are already on their way.
It is extended by one input-disturbance state b (V), on by default::

    x[k+1] = A x[k] + B (u[k] + b[k] + w[k]),    b[k+1] = b[k] + w_b[k],    y[k] = x_1[k] + v[k]

What the estimate represents. The measured speed y[k] is a whole-count encoder difference over
the last tick: the *average* of the true speed over [k − 1, k], about the true speed half a tick
earlier. The model is fitted to that, so x̂_1[k|k] estimates the same average. The true speed *now*,
at tick k, lies between that average and the next one, which the model predicts from the voltages
already sent::

    ω̂[k] = (x̂_1[k|k] + x̂_1[k+1|k]) / 2,    x̂_1[k+1|k] = (A x̂[k|k] + B u[k])_1

(exact for a speed that changes linearly over the two ticks). The state-feedback controller
reports ω̂ as its estimate (:mod:`cartctl.runtime.statefeedback`); the PI, designed on the model
of the measured speed, acts on x̂_1[k|k].

- w (V std ``process_noise_std_v``): an input-equivalent voltage disturbance standing for PWM
  rounding (47 mV steps: 14 mV std), the part of friction that varies fast, and model error. The
  default 0.1 V is a few percent of a typical 3–6 V command; on the cart simulator 0.05–0.1 V gave
  the smallest speed error, 0.2 V a third more.
- b (a random walk, step std ``bias_drift_std_v`` per tick): the slowly varying part of that
  disturbance, mainly dry friction and rolling resistance (≈ 0.8 V on the ground, changing sign
  with the direction: an offset the ARX model cannot represent), and the model's DC error.
  Without it the estimate carries that static error (±0.5 rad/s on the physics simulator in
  steady state, following the sign of the friction); with it the estimate is offset-free, and
  pole placement uses b̂ as its integral action (:mod:`cartctl.design.poles`). The default 0.03 V
  per tick gives b a time constant of about 40 ms (its estimator pole ≈ 0.78 on the ground
  models): 0.01 (pole ≈ 0.92) leaves the friction wrong for longer after each reversal, 0.1
  lets the quantisation into b̂ (the steady-state estimate error nearly doubles) and costs pole
  placement 15–20° of phase margin. 0 leaves the state out.
- v (variance R): the encoder quantisation. The speed is a whole-count difference over one tick,
  q = (2π / counts_per_rev) / Ts rad/s per count (0.3506 rad/s for 1792 counts and 10 ms). Each
  count reading floors the angle, an error uniform on [0, 1) count (variance 1/12 count²); the
  difference of two such errors has variance 1/6 count², so R = q² / 6 + (extra noise)². This
  treats the errors of successive speeds as white, which they are not (they are the differences of
  one white sequence, so neighbours correlate by −½, and at a whole number of counts per tick the
  error freezes); it is the usual simplification.

The gain is the steady-state *filter* gain L = P Cᵀ (C P Cᵀ + R)⁻¹, with P the a priori (predicted)
covariance, the stabilising solution of the filter DARE ``P = A P Aᵀ − A P Cᵀ (C P Cᵀ + R)⁻¹ C P Aᵀ
+ Q``. It corrects the prediction with the measurement of the same tick: x̂[k|k] = x̂[k|k−1] +
L (y[k] − C x̂[k|k−1]); a Kalman filter's time-varying gain converges to it. ``control.dlqe`` returns the
*predictor* gain A L instead. The estimation error of x̂[k|k] evolves with (I − L C) A, whose
eigenvalues are the estimator poles.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import ENCODER_COUNTS_PER_REV, encoder_quantum_rad_s
from cartctl.design.request import DEFAULT_BIAS_DRIFT_STD_V, DEFAULT_PROCESS_NOISE_STD_V
from cartctl.design.statespace import StateSpace, realise
from cartctl.errors import InputError
from cartctl.model import ArxModel
from cartctl.runtime.kalman import KalmanDesign

__all__ = [
    "DEFAULT_BIAS_DRIFT_STD_V",
    "DEFAULT_PROCESS_NOISE_STD_V",
    "KalmanDesign",
    "design_kalman",
    "quantisation_std_rad_s",
]


def quantisation_std_rad_s(period_s: float, counts_per_rev: int = ENCODER_COUNTS_PER_REV) -> float:
    """Standard deviation (rad/s) of the quantisation error of a whole-count speed: q / √6.

    q is one count per tick (:func:`~cartctl.cart.encoder_quantum_rad_s`); the error is the
    difference of two independent errors uniform over one count (variance 2 × q²/12).
    """
    return encoder_quantum_rad_s(period_s, counts_per_rev) / math.sqrt(6.0)


def _nonnegative(name: str, value: float, *, positive: bool = False) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
        need = "> 0" if positive else ">= 0"
        raise InputError(f"{name} must be a finite number {need}, got {value}")
    return value


def _frozen(a: NDArray[np.float64]) -> NDArray[np.float64]:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


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
    """Design the steady-state Kalman filter (see the module docstring for the model).

    Parameters
    ----------
    plant : ArxModel or StateSpace
        The motor model, or its realisation from :func:`~cartctl.design.statespace.realise`.
    process_noise_std_v : float
        σ_w, white input-equivalent voltage disturbance (V), > 0.
    bias_drift_std_v : float
        σ_b, random-walk step of the input-disturbance state (V per tick); 0 leaves it out.
    extra_noise_std_rad_s : float
        Measurement noise beyond the quantisation (rad/s std, ``--measurement-noise``), added in
        variance: the result's ``measurement_noise_std_rad_s`` is the total √R.
    counts_per_rev : int
        Encoder counts per wheel revolution (sets the quantisation step).
    extra_delay_ticks : int
        With an ArxModel: extra ticks of input delay to realise (see ``realise``). Must be 0 with
        a StateSpace (which has its delay built in).
    timing_noise_std_ticks : float
        σ_ε, the uncertainty (std, ticks) of when a command lands, for the time-varying filter's
        Q[k] = Q + (σ_ε Δu[k])² B Bᵀ (see :class:`~cartctl.runtime.kalman.KalmanDesign`); it
        does not change the steady-state P and L, which hold while the command is constant.

    Returns
    -------
    KalmanDesign

    Raises
    ------
    InputError
        A noise level that is negative, non-finite, or zero where it must not be; a bad count; no
        stabilising DARE solution.
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
    B = np.zeros(m)
    B[:n] = plant.B
    C = np.zeros(m)
    C[:n] = plant.C
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
    return KalmanDesign(
        A=_frozen(A),
        B=_frozen(B),
        C=_frozen(C),
        Q=_frozen(Q),
        R=float(R),
        P=_frozen(P),
        L=_frozen(L),
        n_model_states=n,
        period_s=plant.period_s,
        process_noise_std_v=sw,
        bias_drift_std_v=sb,
        measurement_noise_std_rad_s=math.sqrt(R),
        timing_noise_std_ticks=timing,
    )
