"""The runtime interfaces: a per-motor controller and a speed estimator, stepped once per tick.

Tick order, per motor, at tick k (the loop and the closed-loop analysis both follow it)::

    y = measured speed at tick k
    u = controller.step(reference_k, y)    # voltage for tick k, already within ±voltage_limit_v
    send u                                 # the controller has told its estimator about u itself

A controller that runs on an estimate owns its estimator: ``step`` first corrects the estimator
with y, computes u from the estimate, then lets the estimator predict with u. ``estimate_rad_s``
is the speed the controller acted on (the measurement itself when there is no estimator).
Everything is plain floats: no clock, no I/O, cheap enough for a fast simulated loop.
"""

from __future__ import annotations

from typing import Literal, Protocol, get_args, runtime_checkable

AntiWindup = Literal["conditional", "back-calculation", "none"]
ANTI_WINDUP: tuple[str, ...] = get_args(AntiWindup)
"""The PI's anti-windup modes, in :class:`~cartctl.runtime.pi.PiController`'s order (here, where
the command line's parser takes them without loading numpy)."""


@runtime_checkable
class SpeedEstimator(Protocol):
    """Estimates a motor's speed from its quantised measurement and the applied voltage."""

    def reset(self) -> None:
        """Back to rest (state and covariance at their initial values)."""
        ...

    def correct(self, measured_rad_s: float) -> float:
        """Take the measurement of this tick; return the speed estimate for this tick (rad/s)."""
        ...

    def predict(self, voltage_v: float) -> None:
        """Propagate to the next tick with the voltage commanded at this tick (V)."""
        ...


@runtime_checkable
class Controller(Protocol):
    """One motor's speed controller."""

    voltage_limit_v: float
    """The command never leaves ±voltage_limit_v (V)."""

    estimate_rad_s: float
    """The speed the last ``step`` acted on (rad/s)."""

    def reset(self) -> None:
        """Back to rest (integrators and estimator state cleared)."""
        ...

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float:
        """One tick: return the voltage command (V), within ±voltage_limit_v."""
        ...
