"""Response to a load disturbance: a step of d volts added at the plant input, reference held at 0.

Where it sits: after a design, beside the reference step of :mod:`cartctl.design.analysis`, for
``cartctl design``. A load torque on the wheel (a slope, a push) acts like a voltage added to the
motor's own: the plant sees v[k] = u[k − extra] + d, where ``extra`` is the design's delay beyond
the model's (a serial link delays the command, not the load). The runtime controller (with its
estimator, integral action, anti-windup and voltage limit) runs as in the 10 ms loop with r = 0,
so the speed y is the deviation the disturbance causes. Linear and unsaturated this is::

    Y(z) = G(z) / (1 + L(z)) · D(z),       L = C_fb·G·z^(−extra)

A controller with integral action brings y back to 0 (the final-value theorem: 1 + L has a pole at
z = 1). The recovery time is the first time after which |y| stays within
``RECOVERY_FRACTION`` of the peak deviation. Pure: no clock, no I/O.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.base import Controller

__all__ = ["RECOVERY_FRACTION", "DisturbanceResponse", "simulate_disturbance"]

RECOVERY_FRACTION = 0.02
"""The deviation counts as recovered once it stays within this fraction of its peak (2 %)."""

DEFAULT_DISTURBANCE_V = 1.0
"""The default step at the plant input (V)."""


@dataclass(frozen=True, eq=False)
class DisturbanceResponse:
    """A simulated load-disturbance step.

    Attributes
    ----------
    time_s : ndarray, shape (n,)
        From the step, at t = 0 (s).
    speed_rad_s : ndarray, shape (n,)
        The speed deviation y from the reference 0 (rad/s).
    voltage_v : ndarray, shape (n,)
        The controller's command u (V); it settles at −d when the controller rejects the load.
    disturbance_v : float
        The step d (V).
    """

    time_s: NDArray[np.float64]
    speed_rad_s: NDArray[np.float64]
    voltage_v: NDArray[np.float64]
    disturbance_v: float

    @property
    def peak_index(self) -> int:
        """The tick of the largest |deviation|."""
        return int(np.argmax(np.abs(self.speed_rad_s)))

    @property
    def peak_deviation_rad_s(self) -> float:
        """The deviation of largest magnitude, with its sign (rad/s)."""
        return float(self.speed_rad_s[self.peak_index])

    @property
    def recovery_band_rad_s(self) -> float:
        """``RECOVERY_FRACTION`` of the peak |deviation| (rad/s)."""
        return RECOVERY_FRACTION * abs(self.peak_deviation_rad_s)

    @property
    def recovery_time_s(self) -> float | None:
        """First time after the peak from which |y| stays within the band (s); None if never."""
        outside = np.flatnonzero(np.abs(self.speed_rad_s) > self.recovery_band_rad_s)
        if outside.size == 0 or outside[-1] == self.speed_rad_s.size - 1:
            return None
        return float(self.time_s[outside[-1] + 1])

    def to_dict(self) -> dict[str, Any]:
        """The ``disturbance`` entry of ``design --json``."""
        return {
            "step_v": self.disturbance_v,
            "peak_deviation_rad_s": self.peak_deviation_rad_s,
            "peak_time_s": float(self.time_s[self.peak_index]),
            "recovery_time_s": self.recovery_time_s,
            "recovery_band_rad_s": self.recovery_band_rad_s,
            "final_deviation_rad_s": float(self.speed_rad_s[-1]),
            "final_voltage_v": float(self.voltage_v[-1]),
        }


def simulate_disturbance(
    controller: Controller,
    model: ArxModel,
    *,
    disturbance_v: float = DEFAULT_DISTURBANCE_V,
    duration_s: float = 2.0,
    extra_delay_ticks: int = 0,
) -> DisturbanceResponse:
    """Add ``disturbance_v`` at the plant input from t = 0 and run the loop with r = 0.

    Parameters
    ----------
    controller : Controller
        A runtime controller; it is reset first.
    model : ArxModel
        The plant (its own delay included); the sum u + d is saturated at ±12 V like the cart.
    disturbance_v : float
        The step d (V).
    duration_s : float
        Simulated time (s).
    extra_delay_ticks : int
        Ticks by which the command (not the load) is delayed beyond the model's delay.
    """
    plant = ArxPlant(model, model)
    n = max(2, round(duration_s / model.period_s))
    d = float(disturbance_v)
    speed, voltage = np.zeros(n), np.zeros(n)
    queue: deque[float] = deque([0.0] * int(extra_delay_ticks))
    controller.reset()
    y = plant.reset().speed_a_rad_s
    for k in range(n):
        u = controller.step(0.0, y)
        speed[k], voltage[k] = y, u
        queue.append(u)
        y = plant.step(queue.popleft() + d, 0.0).speed_a_rad_s
    return DisturbanceResponse(np.arange(n, dtype=np.float64) * model.period_s, speed, voltage, d)
