"""Closed-loop step analysis: the runtime controller against the model, with saturation.

The same per-tick objects that the 10 ms loop runs (:mod:`cartctl.runtime`) are stepped against the
model as a simulated plant (saturated at the supply), following the tick order of
:mod:`cartctl.runtime.base`. Pure: no clock, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.measures.stepinfo import StepInfo, step_info
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.base import Controller


@dataclass(frozen=True)
class StepAnalysis:
    """A simulated closed-loop step.

    Attributes
    ----------
    time_s, reference_rad_s, speed_rad_s, estimate_rad_s, voltage_v : ndarray, shape (n,)
        Per tick: time (s), reference, modelled speed, the speed the controller acted on, and
        the voltage command (V).
    info : StepInfo
        Rise, overshoot, settling and steady-state error against the reference.
    """

    time_s: NDArray[np.float64]
    reference_rad_s: NDArray[np.float64]
    speed_rad_s: NDArray[np.float64]
    estimate_rad_s: NDArray[np.float64]
    voltage_v: NDArray[np.float64]
    info: StepInfo

    @property
    def peak_voltage_v(self) -> float:
        """Largest |voltage| commanded (V)."""
        return float(np.max(np.abs(self.voltage_v)))

    def to_dict(self) -> dict[str, Any]:
        """``design --json``'s ``step`` entry (plus the full step info and the peak voltage)."""
        info = self.info.to_dict()
        return {
            "overshoot_percent": info["overshoot_percent"],
            "settling_time_s": info["settling_time_s"],
            "rise_time_s": info["rise_time_s"],
            "steady_state_error": info["steady_state_error"],
            "peak_voltage_v": self.peak_voltage_v,
            "step_rad_s": float(self.reference_rad_s[-1]),
        }


def simulate_step(
    controller: Controller,
    model: ArxModel,
    *,
    step_rad_s: float = 10.0,
    duration_s: float = 2.0,
    extra_delay_ticks: int = 0,
) -> StepAnalysis:
    """Step the reference from 0 to ``step_rad_s`` at t = 0 and run the closed loop.

    Parameters
    ----------
    controller : Controller
        A runtime controller; it is reset first.
    model : ArxModel
        The plant (its own delay included); saturated at ±12 V like the cart.
    step_rad_s : float
        Reference step (rad/s).
    duration_s : float
        Simulated time (s).
    extra_delay_ticks : int
        Ticks of delay added to the model's, as a PC-side serial loop adds.
    """
    plant_model = model.with_extra_delay(extra_delay_ticks)
    plant = ArxPlant(plant_model, plant_model)
    n = max(2, round(duration_s / model.period_s))
    ref = np.full(n, float(step_rad_s))
    speed, estimate, voltage = np.zeros(n), np.zeros(n), np.zeros(n)
    controller.reset()
    y = plant.reset().speed_a_rad_s
    for k in range(n):
        u = controller.step(ref[k], y)
        speed[k], estimate[k], voltage[k] = y, controller.estimate_rad_s, u
        y = plant.step(u, 0.0).speed_a_rad_s
    time_s = np.arange(n, dtype=np.float64) * model.period_s
    info = step_info(time_s, speed, reference=float(step_rad_s), initial=0.0, onset_s=0.0)
    return StepAnalysis(time_s, ref, speed, estimate, voltage, info)
