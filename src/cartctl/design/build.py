"""From controller files to runtime controllers: a ``[motors.X]`` entry holds the design's
result itself (gains, estimator matrices), so the loop runs exactly what was designed."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from cartctl.cart import check_voltage_limit
from cartctl.design.controller_ss import feedback_gains, kalman_from_entry
from cartctl.design.controllerfile import ControllerFile
from cartctl.design.kalman import KalmanDesign
from cartctl.errors import DataFileError
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController


def make_estimator(design: KalmanDesign) -> KalmanSpeedEstimator | SteadyStateSpeedEstimator:
    """The runtime estimator of a design: the fixed steady-state gain L (a design's P is
    stationary), or, with timing noise, the filter whose gain moves at every command change. A
    file's ``estimator_gain`` key (older versions) is ignored."""
    if design.timing_noise_std_ticks > 0.0:
        return KalmanSpeedEstimator(design)
    return SteadyStateSpeedEstimator(design)


def build_controller(
    method: str, entry: Mapping[str, Any], period_s: float, voltage_limit_v: float
) -> Controller:
    """One motor's runtime controller from its ``[motors.X]`` entry; KeyError, TypeError or
    ValueError for a key missing or not fitting."""
    if method == "pi":
        est = entry.get("estimator")
        return PiController(
            float(entry["kp"]),
            float(entry["ki"]),
            period_s,
            voltage_limit_v=voltage_limit_v,
            anti_windup=str(entry.get("anti_windup", "conditional")),
            estimator=None if est is None else make_estimator(kalman_from_entry(est)),
        )
    gains = feedback_gains(entry, period_s)
    estimator = make_estimator(gains.estimator)
    return StateFeedbackController(gains, estimator=estimator, voltage_limit_v=voltage_limit_v)


def build_controllers(
    controller: ControllerFile, *, voltage_limit_v: float | None = None
) -> dict[str, Controller]:
    """The runtime controller of each motor in a controller file, limited to ``voltage_limit_v``
    (V; at most, and by default, the file's): DataFileError for a motor entry that misses a key
    or holds inconsistent numbers, InputError for a limit above the file's."""
    limit = controller.voltage_limit_v
    if voltage_limit_v is not None:  # at most the file's limit
        limit = check_voltage_limit(voltage_limit_v, most_v=limit)
    out: dict[str, Controller] = {}
    for motor, entry in controller.motors.items():
        try:
            out[motor] = build_controller(controller.method, entry, controller.period_s, limit)
        except (KeyError, TypeError, ValueError) as exc:
            why = f" misses {exc.args[0]}" if isinstance(exc, KeyError) else f": {exc}"
            raise DataFileError(
                controller.path or "controller file", f"[motors.{motor}]{why}"
            ) from None
    return out
