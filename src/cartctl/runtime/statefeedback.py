"""The pole-placement speed controller: state feedback on a Kalman estimate, with integral action.

Where it sits: the runtime, one object per motor, stepped once per tick by the loop; it runs a
:class:`~cartctl.design.poles.PolesDesign`. Per tick, in the order of :mod:`cartctl.runtime.base`::

    x̂      = estimator.correct(y[k])                      # x̂[k|k]
    u_raw  = Kr r[k] − K x̂ − Ki x_i                          (V)
    u      = clamp(u_raw, ±voltage_limit_v)
    x_i   += Ts (r[k] − y[k])    unless u is saturated and the error would drive it further
    estimator.predict(u)                                   # x̂[k+1|k], with the clamped voltage
    estimate = (x̂_1[k|k] + x̂_1[k+1|k]) / 2                 # the true speed now (rad/s)

K covers the whole estimator state: with the input-disturbance state its last entry is 1, so
u carries −b̂, the integral action, and Ki is 0 (see :mod:`cartctl.design.poles`). The estimate
reported is the true speed at tick k: the measured speed is the average over the last tick, which
x̂_1[k|k] estimates, and the true speed now lies half-way to the next tick's average, which the
prediction gives (see :mod:`cartctl.design.kalman`). On ``--plant sim`` the "true" speed is the
model's output, itself a tick average, so there this estimate leads it by half a tick.

The integrator stops only while it would push the command deeper into saturation (conditional
integration), so it never winds up, and the estimator always predicts with the voltage actually
sent, so it does not wind up either. A non-finite reference or measurement gives 0 V for that
tick: the integrator holds, the estimator skips the correction and predicts with 0 V. A command
that overflows (after an absurd measurement such as 1e308 rad/s) gives 0 V and resets the
controller, so it recovers instead of holding a poisoned state.
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
from cartctl.runtime.kalman import KalmanDesign, StateEstimator, SteadyStateSpeedEstimator

__all__ = ["StateFeedbackController", "feedback_law"]


def feedback_law(
    reference_rad_s: float | Value,
    measured_rad_s: Value,
    state: Sequence[Value],
    integral_rad: Value,
    gains: FeedbackTerms,
    limit_v: float,
) -> tuple[Value, Value, Value]:
    """One tick of state feedback with conditional integration (the module docstring's law).

    Works on floats (one controller) and on arrays of shape (N,) (one setting per element, as
    ``cartctl tune --robust`` runs them), with the same operations.

    Parameters
    ----------
    reference_rad_s, measured_rad_s : float or ndarray
        r[k] and y[k] (rad/s), finite.
    state : sequence of float or ndarray
        x̂[k|k], at least as many entries as K.
    integral_rad : float or ndarray
        x_i before this tick (rad).
    gains : FeedbackTerms
        K, Ki, Kr and Ts.
    limit_v : float
        The clamp (V).

    Returns
    -------
    (u_raw, u, integral) : float or ndarray
        The command before and after the clamp (V), and x_i after this tick (rad).
    """
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
    """What the controller needs of a design: a :class:`~cartctl.design.poles.PolesDesign`, or
    the same numbers read back from a controller file."""

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
    """A design's gains as plain floats: K (one per state fed back, V per state unit), Ki
    (V/rad), Kr (V/(rad/s)) and Ts (s)."""

    K: tuple[float, ...]
    Ki: float
    Kr: float
    period_s: float


class StateFeedbackController:
    """Pole-placement speed control with integral action on a Kalman state estimate.

    Parameters
    ----------
    design : FeedbackGains
        K (one gain per estimator state fed back), Ki, Kr and Ts come from here.
    estimator : StateEstimator, optional
        Owned by the controller (reset with it). Its state must start with the states K acts
        on; default a :class:`SteadyStateSpeedEstimator` on ``design.estimator``.
    voltage_limit_v : float
        The command stays within ±voltage_limit_v (V), 0 < limit ≤ 12.

    Attributes
    ----------
    estimate_rad_s : float
        The estimate of the true speed at the last step's tick, (x̂_1[k|k] + x̂_1[k+1|k]) / 2
        (rad/s).
    integral_rad : float
        The integrator state x_i, the integral of (r − y) (rad of wheel angle); it acts only
        when Ki ≠ 0.
    saturated : bool
        Whether the last command hit the limit.
    """

    def __init__(
        self,
        design: FeedbackGains,
        *,
        estimator: StateEstimator | None = None,
        voltage_limit_v: float = SUPPLY_V,
    ) -> None:
        limit = check_voltage_limit(voltage_limit_v, "voltage_limit_v")
        if estimator is None:
            estimator = SteadyStateSpeedEstimator(design.estimator)
        n = design.K.size
        if not isinstance(estimator, StateEstimator) or estimator.state.size < n:
            raise InputError(
                f"the estimator must expose a state of at least {n} values (the design's "
                f"realisation), got {type(estimator).__name__}"
            )
        self.design = design
        self.estimator = estimator
        values = getattr(estimator, "state_values", None)  # a list, without a numpy array
        self._state_values = values if callable(values) else lambda: estimator.state.tolist()
        self.voltage_limit_v = limit
        self.terms = FeedbackTerms(tuple(float(k) for k in design.K), float(design.Ki),
                                   float(design.Kr), float(design.period_s))  # fmt: skip
        """The gains :func:`feedback_law` runs (read only)."""
        self.reset()

    def reset(self) -> None:
        """Integrator cleared, estimator at rest."""
        self.estimator.reset()
        self.integral_rad = 0.0
        self.estimate_rad_s = 0.0
        self.saturated = False

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float:
        """One tick (see the module docstring); return the voltage command (V)."""
        est = self.estimator
        if not math.isfinite(measured_rad_s) or not math.isfinite(reference_rad_s):
            if math.isfinite(measured_rad_s):
                est.correct(measured_rad_s)
            self._predict_and_estimate(float(est.state[0]), 0.0)
            self.saturated = False
            return 0.0
        x1 = est.correct(measured_rad_s)
        u_raw, u, integral = feedback_law(reference_rad_s, measured_rad_s, self._state_values(),
                                          self.integral_rad, self.terms, self.voltage_limit_v)  # fmt: skip
        if not math.isfinite(u_raw):  # overflowed on an absurd value: 0 V and start afresh
            self.reset()
            self._predict_and_estimate(0.0, 0.0)
            return 0.0
        self.integral_rad = integral
        self.saturated = u != u_raw
        self._predict_and_estimate(x1, u)
        return u

    def _predict_and_estimate(self, filtered_rad_s: float, voltage_v: float) -> None:
        """Predict with the voltage sent; the estimate is the mean of x̂_1[k|k] and x̂_1[k+1|k]."""
        self.estimator.predict(voltage_v)
        self.estimate_rad_s = 0.5 * (filtered_rad_s + self._state_values()[0])
