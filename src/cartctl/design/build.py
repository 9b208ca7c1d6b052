"""From designs to controller-file entries, and from controller files to runtime controllers.

A ``[motors.X]`` entry holds the result itself (gains, estimator matrices), so the loop runs
exactly what was designed, and C(z) (``controller_num``/``controller_den``) for independent
checks, which loading compares with the gains.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from cartctl.cart import check_voltage_limit
from cartctl.design.controller_ss import feedback_gains, feedback_tf_coeffs, kalman_from_entry
from cartctl.design.controllerfile import ControllerFile
from cartctl.design.kalman import KalmanDesign
from cartctl.design.pi import PiDesign
from cartctl.design.poles import PolesDesign
from cartctl.errors import DataFileError
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController


def kalman_entry(design: KalmanDesign) -> dict[str, Any]:
    """The estimator's matrices and noise levels, as a file stores them;
    ``timing_noise_std_ticks`` only when not 0 (files from before it stay the same)."""
    entry = {f.name: getattr(design, f.name) for f in fields(design)}
    if not entry["timing_noise_std_ticks"]:
        del entry["timing_noise_std_ticks"]
    return entry


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
    """A pole-placement design's ``[motors.X]`` entry, with its feedback C(z)."""
    controller_num, controller_den = feedback_tf_coeffs(design)
    return {
        "K": design.K,
        "Ki": design.Ki,
        "Kr": design.Kr,
        "controller_num": controller_num,
        "controller_den": controller_den,
        "closed_loop_poles": [[p.real, p.imag] for p in design.poles],
        "estimator": kalman_entry(design.estimator),
    }


def make_estimator(design: KalmanDesign) -> KalmanSpeedEstimator | SteadyStateSpeedEstimator:
    """The runtime estimator of a design: the fixed steady-state gain L (a design's P is
    stationary), or, with timing noise, the filter whose gain moves at every command change. A
    file's ``estimator_gain`` key (older versions) is ignored."""
    if design.timing_noise_std_ticks > 0.0:
        return KalmanSpeedEstimator(design)
    return SteadyStateSpeedEstimator(design)


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
            if controller.method == "pi":
                est = entry.get("estimator")
                out[motor] = PiController(
                    float(entry["kp"]),
                    float(entry["ki"]),
                    controller.period_s,
                    voltage_limit_v=limit,
                    anti_windup=str(entry.get("anti_windup", "conditional")),
                    estimator=None if est is None else make_estimator(kalman_from_entry(est)),
                )
            else:
                gains = feedback_gains(entry, controller.period_s)
                estimator = make_estimator(gains.estimator)
                out[motor] = StateFeedbackController(
                    gains, estimator=estimator, voltage_limit_v=limit
                )
        except (KeyError, TypeError, ValueError) as exc:
            why = f" misses {exc.args[0]}" if isinstance(exc, KeyError) else f": {exc}"
            raise DataFileError(
                controller.path or "controller file", f"[motors.{motor}]{why}"
            ) from None
    return out
