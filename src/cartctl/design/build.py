"""From designs to controller-file entries, and from controller files to runtime controllers.

A ``[motors.X]`` entry holds the result itself (gains, estimator matrices), so the loop runs
exactly what was designed without re-designing: :func:`build_controllers` reads the numbers back.
It also holds the controller's transfer function C(z) (``controller_num``/``controller_den``,
descending powers of z) for independent checks; :func:`consistency_problems` checks that the two
agree, so a hand-edited file cannot say one controller and run another.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import check_voltage_limit
from cartctl.design.controllerfile import ControllerFile
from cartctl.design.entries import feedback_gains, kalman_from_entry
from cartctl.design.kalman import KalmanDesign
from cartctl.design.pi import PiDesign
from cartctl.design.poles import PolesDesign
from cartctl.errors import DataFileError
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController


def kalman_entry(design: KalmanDesign) -> dict[str, Any]:
    """The estimator's matrices and noise levels, as stored in a controller file.

    ``timing_noise_std_ticks`` only when it is not 0, so a design without it writes the same
    file as before it existed (and a file without it loads with 0).
    """
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


def poles_entry(
    design: PolesDesign,
    controller_num: NDArray[np.float64] | None = None,
    controller_den: NDArray[np.float64] | None = None,
) -> dict[str, Any]:
    """A pole-placement design's ``[motors.X]`` entry.

    ``controller_num``/``controller_den`` are the feedback C(z) of
    :func:`cartctl.design.controller_ss.feedback_tf_coeffs` (computed here when not given).
    """
    if controller_num is None or controller_den is None:
        from cartctl.design.controller_ss import feedback_tf_coeffs

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
    """The runtime estimator of a design: the fixed steady-state gain L, or, with timing noise
    (``timing_noise_std_ticks`` > 0), the filter whose gain moves at every change of the command.

    A design's P is the stationary covariance, so without timing noise the gain is L at every
    tick. A controller file's ``estimator_gain`` key (written by older versions) is ignored.
    """
    if design.timing_noise_std_ticks > 0.0:
        return KalmanSpeedEstimator(design)
    return SteadyStateSpeedEstimator(design)


def build_controllers(
    controller: ControllerFile, *, voltage_limit_v: float | None = None
) -> dict[str, Controller]:
    """The runtime controller of each motor in a controller file.

    Parameters
    ----------
    controller : ControllerFile
    voltage_limit_v : float, optional
        The command limit (V) the controllers, their anti-windup and their estimators work with:
        at most the file's ``voltage_limit_v`` (the default).

    Raises
    ------
    DataFileError
        A motor entry misses a key or holds inconsistent numbers.
    InputError
        A voltage limit above the file's, or not in (0, 12] V.
    """
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
                out[motor] = StateFeedbackController(
                    gains,
                    estimator=make_estimator(gains.estimator),
                    voltage_limit_v=limit,
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
