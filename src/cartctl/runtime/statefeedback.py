"""The pole-placement speed controller: state feedback on a Kalman estimate, with integral action.

One object per motor, running a :class:`~cartctl.design.poles.PolesDesign`. Per tick::

    x̂      = estimator.correct(y[k])                      # x̂[k|k]
    u_raw  = Kr r[k] − K x̂ − Ki x_i                          (V)
    u      = clamp(u_raw, ±voltage_limit_v)
    x_i   += Ts (r[k] − y[k])    unless u is saturated and the error would drive it further
    estimator.predict(u)                                   # x̂[k+1|k], with the clamped voltage
    estimate = (x̂_1[k|k] + x̂_1[k+1|k]) / 2                 # the true speed now (rad/s)

With the input-disturbance state, K's last entry is 1 (u carries −b̂, the integral action) and Ki
is 0. The estimate lies half-way between the filtered and the predicted tick averages (on
``--plant sim``, whose output is itself a tick average, it leads by half a tick). A non-finite
reference or measurement gives 0 V for that tick (integrator held, no correction); a command that
overflows (an absurd measurement) gives 0 V and resets the controller.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import SUPPLY_V, check_voltage_limit
from cartctl.errors import InputError
from cartctl.runtime.elementwise import Value, clip, select
from cartctl.runtime.kalman import KalmanDesign, KalmanSpeedEstimator, SteadyStateSpeedEstimator

__all__ = ["StateFeedbackController", "feedback_law"]


def feedback_law(
    reference_rad_s: float | Value,
    measured_rad_s: Value,
    state: Sequence[Value],
    integral_rad: Value,
    gains: FeedbackTerms,
    limit_v: float,
) -> tuple[Value, Value, Value]:
    """One tick of the module docstring's law: (u_raw, u, x_i after the tick) in V, V, rad, from
    finite r[k] and y[k] (rad/s), x̂[k|k] and x_i (rad); floats or arrays."""
    K, ki, k_r, period_s = gains
    u_raw = k_r * reference_rad_s - ki * integral_rad
    for k, xk in zip(K, state, strict=False):
        u_raw = u_raw - k * xk
    u = clip(u_raw, limit_v)
    error = reference_rad_s - measured_rad_s
    # the integrator moves u by −Ki·Ts·error next tick: hold it if that deepens saturation
    grow = (u == u_raw) | ((u_raw > u) != (-ki * error > 0.0))
    return u_raw, u, select(grow, integral_rad + period_s * error, integral_rad)


class FeedbackGains(Protocol):
    """What the controller needs of a design (a PolesDesign, or one read from a file)."""

    @property
    def K(self) -> NDArray[np.float64]: ...  # noqa: N802 (the literature's K)
    @property
    def Ki(self) -> float: ...  # noqa: N802
    @property
    def Kr(self) -> float: ...  # noqa: N802
    @property
    def estimator(self) -> KalmanDesign: ...
    @property
    def period_s(self) -> float: ...


class FeedbackTerms(NamedTuple):
    """A design's gains as floats: K (V per state unit), Ki (V/rad), Kr (V/(rad/s)), Ts (s)."""

    K: tuple[float, ...]
    Ki: float
    Kr: float
    period_s: float


class StateFeedbackController:
    """Pole-placement speed control with integral action on a Kalman state estimate.

    The ``estimator`` is owned (reset with the controller), its state starting with the states K
    acts on (default: a :class:`SteadyStateSpeedEstimator` on ``design.estimator``);
    ``integral_rad`` is x_i, the integral of r − y (rad of wheel angle).
    """

    def __init__(
        self,
        design: FeedbackGains,
        *,
        estimator: SteadyStateSpeedEstimator | KalmanSpeedEstimator | None = None,
        voltage_limit_v: float = SUPPLY_V,
    ) -> None:
        limit = check_voltage_limit(voltage_limit_v, "voltage_limit_v")
        if estimator is None:
            estimator = SteadyStateSpeedEstimator(design.estimator)
        if estimator.state.size < design.K.size:
            raise InputError(
                f"the estimator must expose a state of at least {design.K.size} values (the "
                f"design's realisation), got {type(estimator).__name__}"
            )
        self.design = design
        self.estimator = estimator
        # x̂ as a list, without a numpy array where the estimator can
        self._state_values = getattr(estimator, "state_values", lambda: estimator.state.tolist())
        self.voltage_limit_v = limit
        K = tuple(float(k) for k in design.K)
        self.terms = FeedbackTerms(K, float(design.Ki), float(design.Kr), float(design.period_s))
        self.reset()

    def reset(self) -> None:
        self.estimator.reset()
        self.integral_rad = 0.0
        self.estimate_rad_s = 0.0

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float:
        x1 = self.estimator.correct(measured_rad_s)  # a non-finite y corrects nothing
        if not math.isfinite(measured_rad_s) or not math.isfinite(reference_rad_s):
            self._predict_and_estimate(x1, 0.0)
            return 0.0
        r, x = reference_rad_s, self._state_values()
        u_raw, u, integral = feedback_law(
            r, measured_rad_s, x, self.integral_rad, self.terms, self.voltage_limit_v
        )
        if not math.isfinite(u_raw):  # overflowed on an absurd value: 0 V and start afresh
            self.reset()
            self._predict_and_estimate(0.0, 0.0)
            return 0.0
        self.integral_rad = integral
        self._predict_and_estimate(x1, u)
        return u

    def _predict_and_estimate(self, filtered_rad_s: float, voltage_v: float) -> None:
        """Predict with the voltage sent; the estimate is the mean of x̂_1[k|k] and x̂_1[k+1|k]."""
        self.estimator.predict(voltage_v)
        self.estimate_rad_s = 0.5 * (filtered_rad_s + self._state_values()[0])
