"""Closed-loop simulations of a design: the reference step and the load-disturbance step.

The runtime controller (:mod:`cartctl.runtime`, with its estimator, anti-windup and limit) runs
against the model as a plant saturated at the supply, in the tick order of
:mod:`cartctl.runtime.base`. A load torque acts like a voltage d added at the plant input; the
plant sees v[k] = u[k − extra] + d (a serial link delays the command, not the load), so linear
and unsaturated Y(z) = G / (1 + L) · D(z) with L = C_fb·G·z^(−extra). Pure: no clock, no I/O.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.measures.stepinfo import StepInfo, step_info
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.base import Controller

__all__ = ["RECOVERY_FRACTION", "DisturbanceResponse", "simulate_disturbance", "simulate_step"]

RECOVERY_FRACTION = 0.02
"""A disturbance's deviation counts as recovered once it stays within this fraction of its peak."""

DEFAULT_DISTURBANCE_V = 1.0
"""The default load step at the plant input (V)."""


@dataclass(frozen=True)
class StepAnalysis:
    """A simulated closed-loop step, per tick: time (s), reference, modelled speed, the speed
    the controller acted on (rad/s) and the command (V); ``info`` its metrics."""

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
        """``design --json``'s ``step`` entry."""
        info = self.info.to_dict()
        keys = ("overshoot_percent", "settling_time_s", "rise_time_s", "steady_state_error")
        return {
            **{k: info[k] for k in keys},
            "peak_voltage_v": self.peak_voltage_v,
            "step_rad_s": float(self.reference_rad_s[-1]),
        }


def _run(
    controller: Controller,
    plant_model: ArxModel,
    duration_s: float,
    reference: float,
    disturbance_v: float,
    command_delay_ticks: int,
) -> tuple[NDArray[np.float64], ...]:
    """(time, speed, estimate, voltage) of the loop, from rest, the controller reset first."""
    plant = ArxPlant(plant_model, plant_model)
    n = max(2, round(duration_s / plant_model.period_s))
    speed, estimate, voltage = np.zeros(n), np.zeros(n), np.zeros(n)
    queue: deque[float] = deque([0.0] * int(command_delay_ticks))
    controller.reset()
    y = plant.reset().speed_a_rad_s
    for k in range(n):
        u = controller.step(reference, y)
        speed[k], estimate[k], voltage[k] = y, controller.estimate_rad_s, u
        queue.append(u)
        y = plant.step(queue.popleft() + disturbance_v, 0.0).speed_a_rad_s
    return np.arange(n, dtype=np.float64) * plant_model.period_s, speed, estimate, voltage


def simulate_step(
    controller: Controller,
    model: ArxModel,
    *,
    step_rad_s: float = 10.0,
    duration_s: float = 2.0,
    extra_delay_ticks: int = 0,
) -> StepAnalysis:
    """Step the reference from 0 to ``step_rad_s`` (rad/s) at t = 0 and run the closed loop for
    ``duration_s`` on the model with ``extra_delay_ticks`` more ticks of input delay."""
    plant_model = model.with_extra_delay(extra_delay_ticks)
    r = float(step_rad_s)
    time_s, speed, estimate, voltage = _run(controller, plant_model, duration_s, r, 0.0, 0)
    info = step_info(time_s, speed, reference=r, initial=0.0, onset_s=0.0)
    return StepAnalysis(time_s, np.full(time_s.size, r), speed, estimate, voltage, info)


@dataclass(frozen=True, eq=False)
class DisturbanceResponse:
    """A simulated load-disturbance step: from t = 0 (``time_s``, s) the speed deviation y from
    the reference 0 (``speed_rad_s``), the command u (``voltage_v``; it settles at −d when the
    controller rejects the load) and the step d (``disturbance_v``, V)."""

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
    """Add ``disturbance_v`` (V) at the plant input from t = 0 and run the loop with r = 0 for
    ``duration_s``, the command (not the load) delayed by ``extra_delay_ticks``."""
    d = float(disturbance_v)
    time_s, speed, _, voltage = _run(controller, model, duration_s, 0.0, d, extra_delay_ticks)
    return DisturbanceResponse(time_s, speed, voltage, d)
