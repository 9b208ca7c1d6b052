"""The runtime PI speed controller: one motor, one call per 10 ms tick, plain floats.

Runs the gains of :mod:`cartctl.design.pi` in the loop (and in closed-loop simulation). Unsaturated,
it is exactly the designed C(z) = Kp + Ki·Ts·z/(z − 1) from error to voltage::

    e[k] = r[k] − y[k]
    I[k] = I[k−1] + Ki·Ts·e[k]
    u[k] = Kp·e[k] + I[k],   then clamped to ±voltage_limit_v

Anti-windup (what happens to I when the clamp is active):

- ``"none"``: I integrates regardless; after a long saturation it must unwind (overshoot).
- ``"conditional"`` (conditional integration, or clamping): the update is skipped whenever it
  would carry the output further beyond the limit, that is when Kp·e + I[k−1] + Ki·Ts·e lies
  beyond ±limit and e pushes the same way. The integral then moves at most up to the value that
  puts the output exactly on the limit, and never back (if it already was beyond, it is frozen).
- ``"back-calculation"``: after the clamp, I[k] ← I[k] + Kt·(u_sat − u_unsat), so each tick
  removes the fraction Kt of the excess (Kt = 1 puts the output back on the limit at once).
  Default Kt = min(1, Ts·Ki/Kp), a tracking time constant equal to the integral time Kp/Ki.

A non-finite reference or measurement (NaN, ±inf: a lost frame, a bad reference file), or inputs so
absurd that the output overflows, make that tick's command 0 V, the safe value; the integral is
left as it was. With an estimator, a finite measurement still corrects it, and the estimator
always predicts with the command sent.
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

CONDITIONAL, BACK_CALCULATION = 0, 1
"""Indices of the modes in :data:`ANTI_WINDUP`, as :func:`pi_law` takes them."""


def default_tracking_gain(kp: float, ki: float, period_s: float) -> float:
    """Kt = min(1, Ts·Ki/Kp): a tracking time constant equal to the integral time Kp/Ki (1 for
    Kp = 0)."""
    return min(1.0, period_s * ki / kp) if kp > 0.0 else 1.0


def pi_law(
    error: Value,
    integral_v: Value,
    kp: float,
    ki_ts: float,
    kt: float,
    mode: int,
    limit_v: float,
) -> tuple[Value, Value]:
    """One tick of the PI with its clamp and anti-windup (the module docstring's law).

    Works on floats (one controller) and on arrays of shape (N,) (one setting per element, as
    ``cartctl tune --robust`` runs them), with the same operations.

    Parameters
    ----------
    error : float or ndarray
        e[k] = r[k] − y[k] (rad/s).
    integral_v : float or ndarray
        I[k−1] (V).
    kp, ki_ts, kt : float
        Kp (V/(rad/s)), Ki·Ts (V/(rad/s)) and the back-calculation gain Kt (per tick).
    mode : int
        Index of the anti-windup mode in :data:`ANTI_WINDUP`.
    limit_v : float
        The clamp (V).

    Returns
    -------
    (u, integral) : float or ndarray
        u[k] within ±limit_v (V), and I[k] (V); where u would not be finite, 0 V and I[k−1].
    """
    p = kp * error
    integral = integral_v + ki_ts * error
    u = p + integral
    u_sat = clip(u, limit_v)
    clamped = u_sat != u
    if any_true(clamped):
        if mode == CONDITIONAL:  # up to the limit, never further
            held = clamped & (error * u > 0.0)
            edge = u_sat - p
            moved = select(error > 0.0, larger(integral_v, smaller(integral, edge)),
                           smaller(integral_v, larger(integral, edge)))  # fmt: skip
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


class PiController:
    """Discrete PI speed controller with output clamp and anti-windup.

    Implements :class:`cartctl.runtime.base.Controller`.

    Parameters
    ----------
    kp : float
        Proportional gain Kp ≥ 0 (V/(rad/s)).
    ki : float
        Integral gain Ki ≥ 0 (V/rad).
    period_s : float
        Tick period Ts (s).
    voltage_limit_v : float
        The command stays within ±voltage_limit_v; in (0, 12] V.
    anti_windup : {'conditional', 'back-calculation', 'none'}
        See the module docstring.
    tracking_gain : float, optional
        Kt in (0, 1] for back-calculation (dimensionless, per tick); only with that mode.
    estimator : SpeedEstimator, optional
        When given, the PI acts on its estimate instead of the raw measurement: for the Kalman
        estimators x̂_1[k|k], the estimate of the measured (tick-average) speed that the PI's
        design model describes. Its input-disturbance state (on by default in
        :func:`~cartctl.design.kalman.design_kalman`) keeps that estimate offset-free; without
        it the estimate carries friction as a speed offset, and the PI holds the offset.
    """

    __slots__ = (
        "_integral",
        "_ki",
        "_ki_ts",
        "_kp",
        "_kt",
        "_mode",
        "_period_s",
        "anti_windup",
        "estimate_rad_s",
        "estimator",
        "tracking_gain",
        "voltage_limit_v",
    )

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
        self._kp = _finite("Kp", kp, "V/(rad/s)")
        self._ki = _finite("Ki", ki, "V/rad")
        self._period_s = _finite("the period", period_s, "s", positive=True)
        limit = check_voltage_limit(voltage_limit_v)
        if anti_windup not in ANTI_WINDUP:
            raise InputError(
                f"unknown anti-windup {anti_windup!r}; expected one of {', '.join(ANTI_WINDUP)}"
            )
        if tracking_gain is not None:
            if anti_windup != "back-calculation":
                raise InputError(
                    f"tracking_gain applies only to anti_windup='back-calculation', not "
                    f"{anti_windup!r}"
                )
            kt = float(tracking_gain)
            if not (math.isfinite(kt) and 0.0 < kt <= 1.0):
                raise InputError(
                    f"tracking gain Kt must be in (0, 1] per tick, got {tracking_gain}"
                )
        else:
            kt = default_tracking_gain(self._kp, self._ki, self._period_s)
        self.voltage_limit_v = limit
        self.anti_windup = anti_windup
        self.tracking_gain = tracking_gain
        self.estimator = estimator
        self._ki_ts = self._ki * self._period_s
        self._kt = kt
        self._mode = ANTI_WINDUP.index(anti_windup)
        self.reset()

    @property
    def kp(self) -> float:
        """Proportional gain Kp (V/(rad/s)); fixed at construction."""
        return self._kp

    @property
    def ki(self) -> float:
        """Integral gain Ki (V/rad); fixed at construction."""
        return self._ki

    @property
    def period_s(self) -> float:
        """Tick period Ts (s)."""
        return self._period_s

    @property
    def tracking_gain_per_tick(self) -> float:
        """Kt in use for back-calculation: ``tracking_gain``, or its default (per tick)."""
        return self._kt

    @property
    def integral_v(self) -> float:
        """The integral term I (V)."""
        return self._integral

    def reset(self) -> None:
        """Back to rest: integral 0, estimator reset."""
        self._integral = 0.0
        self.estimate_rad_s = 0.0
        if self.estimator is not None:
            self.estimator.reset()

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float:
        """One tick: the voltage command (V) for this tick, within ±voltage_limit_v.

        Parameters
        ----------
        reference_rad_s : float
            Speed reference r[k] (rad/s).
        measured_rad_s : float
            Measured speed y[k] (rad/s).

        Returns
        -------
        float
            u[k] (V); 0 V, with the integral unchanged, when the reference, the measurement or
            the estimate is not finite (``estimate_rad_s`` is then that non-finite value).
        """
        estimator = self.estimator
        y = measured_rad_s
        if estimator is not None and math.isfinite(y):
            y = estimator.correct(y)
        self.estimate_rad_s = y
        u_sat, self._integral = pi_law(reference_rad_s - y, self._integral, self._kp, self._ki_ts,
                                       self._kt, self._mode, self.voltage_limit_v)  # fmt: skip
        if estimator is not None:
            estimator.predict(u_sat)
        return u_sat
