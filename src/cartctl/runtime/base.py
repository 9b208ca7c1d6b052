"""The runtime interfaces: a per-motor controller and a speed estimator, stepped once per tick.

Per motor at tick k, ``u = controller.step(r[k], y[k])`` is the voltage for tick k, already
within ±voltage_limit_v. A controller that runs on an estimate owns its estimator: ``step``
corrects it with y, computes u from the estimate, then lets it predict with u;
``estimate_rad_s`` is the speed it acted on (the measurement itself without an estimator).
"""

from __future__ import annotations

from typing import Literal, Protocol, get_args, runtime_checkable

AntiWindup = Literal["conditional", "back-calculation", "none"]
ANTI_WINDUP: tuple[str, ...] = get_args(AntiWindup)
"""The PI's anti-windup modes (here, where the parser takes them without loading numpy)."""


@runtime_checkable
class SpeedEstimator(Protocol):
    """Estimates a motor's speed from its quantised measurement and the applied voltage."""

    def reset(self) -> None: ...

    def correct(self, measured_rad_s: float) -> float:
        """Take this tick's measurement; return this tick's speed estimate (rad/s)."""

    def predict(self, voltage_v: float) -> None:
        """Propagate to the next tick with the voltage commanded at this tick (V)."""


@runtime_checkable
class Controller(Protocol):
    """One motor's speed controller."""

    voltage_limit_v: float
    estimate_rad_s: float

    def reset(self) -> None: ...

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float: ...
