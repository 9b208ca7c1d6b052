"""From designs to controller-file entries, and from controller files to runtime controllers.

A ``[motors.X]`` entry holds the result itself (gains, estimator matrices), so the loop runs
exactly what was designed without re-designing: :func:`build_controllers` reads the numbers back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.controllerfile import ControllerFile
from cartctl.design.kalman import KalmanDesign
from cartctl.design.pi import PiDesign
from cartctl.design.poles import PolesDesign
from cartctl.errors import DataFileError
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController

ESTIMATOR_GAINS = ("kalman", "steady-state")
"""'kalman': filterpy's KalmanFilter (time-varying gain); 'steady-state': the fixed DARE gain."""

_KALMAN_ARRAYS = ("A", "B", "C", "Q", "P", "L")


def kalman_entry(design: KalmanDesign) -> dict[str, Any]:
    """The estimator's matrices and noise levels, as stored in a controller file."""
    return {f.name: getattr(design, f.name) for f in fields(design)}


def kalman_from_entry(entry: Mapping[str, Any]) -> KalmanDesign:
    """Rebuild a :class:`KalmanDesign` from :func:`kalman_entry`'s table."""
    values = {}
    for f in fields(KalmanDesign):
        if f.name not in entry:
            raise KeyError(f"estimator.{f.name}")
        value = entry[f.name]
        values[f.name] = np.asarray(value, dtype=float) if f.name in _KALMAN_ARRAYS else value
    return KalmanDesign(**values)


def pi_entry(design: PiDesign, anti_windup: str, estimator: KalmanDesign | None) -> dict[str, Any]:
    """A PI design's ``[motors.X]`` entry."""
    num, den = design.controller_tf_coeffs()
    entry: dict[str, Any] = {
        "kp": design.kp,
        "ki": design.ki,
        "anti_windup": anti_windup,
        "controller_num": num,
        "controller_den": den,
    }
    if estimator is not None:
        entry["estimator"] = kalman_entry(estimator)
    return entry


def poles_entry(design: PolesDesign) -> dict[str, Any]:
    """A pole-placement design's ``[motors.X]`` entry."""
    return {
        "K": design.K,
        "Ki": design.Ki,
        "Kr": design.Kr,
        "closed_loop_poles": [[p.real, p.imag] for p in design.poles],
        "estimator": kalman_entry(design.estimator),
    }


@dataclass(frozen=True)
class _Gains:
    """A :class:`~cartctl.runtime.statefeedback.FeedbackGains` rebuilt from a controller file."""

    K: NDArray[np.float64]
    Ki: float
    Kr: float
    period_s: float
    estimator: KalmanDesign


def make_estimator(
    design: KalmanDesign, gain: str
) -> KalmanSpeedEstimator | SteadyStateSpeedEstimator:
    """The runtime estimator for a design: filterpy ('kalman') or fixed gain ('steady-state')."""
    if gain == "kalman":
        return KalmanSpeedEstimator(design)
    return SteadyStateSpeedEstimator(design)


def build_controllers(controller: ControllerFile) -> dict[str, Controller]:
    """The runtime controller of each motor in a controller file.

    Raises
    ------
    DataFileError
        A motor entry misses a key or holds inconsistent numbers.
    """
    gain = str(controller.request.get("estimator_gain", "kalman"))
    if gain not in ESTIMATOR_GAINS:
        raise DataFileError(
            controller.path or "controller file", f"unknown estimator_gain {gain!r}"
        )
    out: dict[str, Controller] = {}
    for motor, entry in controller.motors.items():
        try:
            if controller.method == "pi":
                est = entry.get("estimator")
                out[motor] = PiController(
                    float(entry["kp"]),
                    float(entry["ki"]),
                    controller.period_s,
                    voltage_limit_v=controller.voltage_limit_v,
                    anti_windup=str(entry.get("anti_windup", "conditional")),
                    estimator=None if est is None else make_estimator(kalman_from_entry(est), gain),
                )
            else:
                kalman = kalman_from_entry(entry["estimator"])
                gains = _Gains(
                    np.asarray(entry["K"], dtype=float),
                    float(entry["Ki"]),
                    float(entry["Kr"]),
                    controller.period_s,
                    kalman,
                )
                out[motor] = StateFeedbackController(
                    gains,
                    estimator=make_estimator(kalman, gain),
                    voltage_limit_v=controller.voltage_limit_v,
                )
        except KeyError as exc:
            raise DataFileError(
                controller.path or "controller file", f"[motors.{motor}] misses {exc.args[0]}"
            ) from None
        except (TypeError, ValueError) as exc:
            raise DataFileError(
                controller.path or "controller file", f"[motors.{motor}]: {exc}"
            ) from None
    return out
