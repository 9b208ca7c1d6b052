"""The runtime PI speed controller: one motor, one call per tick, plain floats.

Unsaturated it is exactly the designed C(z) = Kp + Ki·Ts·z/(z − 1) (:mod:`cartctl.design.pi`)::

    e[k] = r[k] − y[k],   I[k] = I[k−1] + Ki·Ts·e[k],   u[k] = Kp·e[k] + I[k], clamped to ±limit

Anti-windup, what happens to I while the clamp is active: ``"none"``, I integrates regardless
(it must unwind after a long saturation: overshoot); ``"conditional"`` (clamping), the update
stops where it would carry the output further beyond the limit (Kp·e + I[k−1] + Ki·Ts·e beyond
±limit with e pushing the same way): I moves at most to the value that puts the output on the
limit, never back, and is frozen if already beyond; ``"back-calculation"``, I[k] ← I[k] +
Kt·(u_sat − u_unsat) after the clamp (Kt = 1 puts the output back on the limit at once).

A non-finite reference or measurement (a lost frame, a bad reference file), or an output that
overflows, gives 0 V for that tick and leaves I as it was; an estimator is still corrected by a
finite measurement and always predicts with the command sent.
"""

from __future__ import annotations

import math

from cartctl.cart import SUPPLY_V, check_voltage_limit
from cartctl.errors import InputError
from cartctl.runtime.base import ANTI_WINDUP, SpeedEstimator
from cartctl.runtime.elementwise import (
    Value,
    all_true,
    any_true,
    clip,
    is_finite,
    larger,
    select,
    smaller,
)

CONDITIONAL, BACK_CALCULATION = 0, 1  # indices in ANTI_WINDUP, as pi_law takes the mode


def pi_law(
    error: Value,
    integral_v: Value,
    kp: float,
    ki_ts: float,
    kt: float,
    mode: int,
    limit_v: float,
) -> tuple[Value, Value]:
    """One tick of the module docstring's law: (u[k] within ±limit_v, I[k]) from e[k] (rad/s) and
    I[k−1] (V), Kp (V/(rad/s)), Ki·Ts (V/(rad/s)), Kt (per tick) and the anti-windup mode's index
    in ``ANTI_WINDUP``; where u would not be finite, 0 V and I[k−1]. Floats or arrays."""
    p = kp * error
    integral = integral_v + ki_ts * error
    u = p + integral
    u_sat = clip(u, limit_v)
    clamped = u_sat != u
    if any_true(clamped):
        if mode == CONDITIONAL:  # up to the limit, never further
            held = clamped & (error * u > 0.0)
            edge = u_sat - p
            up = larger(integral_v, smaller(integral, edge))
            moved = select(error > 0.0, up, smaller(integral_v, larger(integral, edge)))
            integral = select(held, moved, integral)
            u_sat = select(held, clip(p + integral, limit_v), u_sat)
        elif mode == BACK_CALCULATION:
            integral = select(clamped, integral + kt * (u_sat - u), integral)
    finite = is_finite(u)  # False for a non-finite r or y, and for absurd inputs that overflow
    if all_true(finite):
        return u_sat, integral
    return select(finite, u_sat, 0.0), select(finite, integral, integral_v)


def _finite(name: str, value: float, unit: str, *, positive: bool = False) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
        sign = "> 0" if positive else ">= 0"
        raise InputError(f"{name} must be a finite number {sign} {unit}, got {value}")
    return value


def default_tracking_gain(kp: float, ki: float, period_s: float) -> float:
    """Kt per tick when none is given: min(1, Ts·Ki/Kp), 1 for Kp = 0 (a tracking time constant
    equal to the integral time Kp/Ki)."""
    return min(1.0, period_s * ki / kp) if kp > 0.0 else 1.0


class PiController:
    """Discrete PI speed controller with output clamp and anti-windup.

    Kp ≥ 0 (V/(rad/s)), Ki ≥ 0 (V/rad), Ts (s); ``tracking_gain`` is Kt in (0, 1] per tick, for
    back-calculation only (default min(1, Ts·Ki/Kp), 1 for Kp = 0: a tracking time constant equal
    to the integral time). With an ``estimator`` the PI acts on its estimate x̂_1[k|k].
    """

    def __init__(
        self,
        kp: float,
        ki: float,
        period_s: float,
        *,
        voltage_limit_v: float = SUPPLY_V,
        anti_windup: str = "conditional",  # one of AntiWindup, checked here (files, options)
        tracking_gain: float | None = None,
        estimator: SpeedEstimator | None = None,
    ) -> None:
        self.kp = _finite("Kp", kp, "V/(rad/s)")
        self.ki = _finite("Ki", ki, "V/rad")
        self.period_s = _finite("the period", period_s, "s", positive=True)
        limit = check_voltage_limit(voltage_limit_v)
        if anti_windup not in ANTI_WINDUP:
            raise InputError(
                f"unknown anti-windup {anti_windup!r}; expected one of {', '.join(ANTI_WINDUP)}"
            )
        if tracking_gain is None:
            kt = default_tracking_gain(self.kp, self.ki, self.period_s)
        elif anti_windup != "back-calculation":
            raise InputError(
                f"tracking_gain applies only to anti_windup='back-calculation', not {anti_windup!r}"
            )
        else:
            kt = float(tracking_gain)
            if not (math.isfinite(kt) and 0.0 < kt <= 1.0):
                raise InputError(
                    f"tracking gain Kt must be in (0, 1] per tick, got {tracking_gain}"
                )
        self.voltage_limit_v = limit
        self.anti_windup = anti_windup
        self.estimator = estimator
        # pi_law's Kp, Ki·Ts, Kt and mode (the batch loop of tune --robust takes them too)
        self.gains = (self.kp, self.ki * self.period_s, kt, ANTI_WINDUP.index(anti_windup))
        self.reset()

    def reset(self) -> None:
        self.integral_v = 0.0
        self.estimate_rad_s = 0.0
        if self.estimator is not None:
            self.estimator.reset()

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float:
        """One tick: u[k] (V); 0 V, the integral unchanged, when r, y or the estimate is not finite."""
        estimator = self.estimator
        y = measured_rad_s
        if estimator is not None and math.isfinite(y):
            y = estimator.correct(y)
        self.estimate_rad_s = y
        error, limit = reference_rad_s - y, self.voltage_limit_v
        u_sat, self.integral_v = pi_law(error, self.integral_v, *self.gains, limit)
        if estimator is not None:
            estimator.predict(u_sat)
        return u_sat
