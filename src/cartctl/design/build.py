"""From designs to controller-file entries, and from controller files to runtime controllers.

A ``[motors.X]`` entry holds the result itself (gains, estimator matrices), so the loop runs
exactly what was designed without re-designing: :func:`build_controllers` reads the numbers back.
It also holds the controller's transfer function C(z) (``controller_num``/``controller_den``,
descending powers of z) for independent checks; :func:`consistency_problems` checks that the two
agree, so a hand-edited file cannot say one controller and run another.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.controllerfile import ControllerFile
from cartctl.design.kalman import KalmanDesign
from cartctl.design.pi import PiDesign, pi_tf_coeffs
from cartctl.design.poles import PolesDesign
from cartctl.errors import DataFileError, InputError
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController

ESTIMATOR_GAINS = ("kalman", "steady-state")
"""'kalman': filterpy's KalmanFilter (time-varying gain); 'steady-state': the fixed DARE gain."""

_KALMAN_ARRAYS = ("A", "B", "C", "Q", "P", "L")

CONSISTENCY_RTOL = 1e-6
"""How far a stored C(z) coefficient may be from the one its gains give, relative to the largest
coefficient of that polynomial (a file rounds nothing: the rest is floating-point noise)."""


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
    _check_estimator(values)
    return KalmanDesign(**values)


COVARIANCE_BOUND = 1e6
"""Largest covariance entry (rad²/s², V²) an estimator file may hold; the designs hold below 1."""


def _check_estimator(values: Mapping[str, Any]) -> None:
    """Shapes that fit together, finite numbers, and an estimator whose error decays.

    Raises
    ------
    ValueError
        Naming what is wrong (build_controllers reports it with the motor and the file).
    """
    A = values["A"]
    m = A.shape[0] if A.ndim == 2 else -1
    shapes = {"A": (m, m), "B": (m,), "C": (m,), "L": (m,), "Q": (m, m), "P": (m, m)}
    for name, shape in shapes.items():
        array = values[name]
        if m < 1 or array.shape != shape:
            raise ValueError(f"estimator.{name} has shape {array.shape}; expected {shape}")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"estimator.{name} holds a value that is not a finite number")
    r = float(values["R"])
    if not (math.isfinite(r) and 0.0 < r <= COVARIANCE_BOUND):
        raise ValueError(f"estimator.R must be a variance in (0, {COVARIANCE_BOUND:g}], got {r}")
    for name in ("Q", "P"):
        cov = values[name]
        scale = max(1.0, float(np.max(np.abs(cov))))
        if (
            np.max(np.abs(cov)) > COVARIANCE_BOUND
            or np.max(np.abs(cov - cov.T)) > 1e-9 * scale
            or np.min(np.linalg.eigvalsh((cov + cov.T) / 2.0)) < -1e-9 * scale
        ):
            raise ValueError(
                f"estimator.{name} must be a covariance: symmetric, positive semidefinite, "
                f"entries up to {COVARIANCE_BOUND:g}"
            )
    error_dynamics = (np.eye(m) - np.outer(values["L"], values["C"])) @ A
    radius = float(np.max(np.abs(np.linalg.eigvals(error_dynamics))))
    if not radius < 1.0:
        raise ValueError(
            f"the estimator's error does not decay (its poles reach |z| = {radius:.4g}); "
            "redesign the controller"
        )


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
    :func:`cartctl.design.loop.feedback_tf_coeffs` (computed here when not given).
    """
    if controller_num is None or controller_den is None:
        from cartctl.design.loop import feedback_tf_coeffs

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


@dataclass(frozen=True)
class _Gains:
    """A :class:`~cartctl.runtime.statefeedback.FeedbackGains` rebuilt from a controller file."""

    K: NDArray[np.float64]
    Ki: float
    Kr: float
    period_s: float
    estimator: KalmanDesign


def _coeffs(values: Sequence[Any]) -> str:
    """Coefficients for a message; an entry that is not a number is shown as it is."""
    return (
        "["
        + ", ".join(
            f"{v:.10g}" if isinstance(v, int | float) and not isinstance(v, bool) else repr(v)
            for v in values
        )
        + "]"
    )


def _disagrees(stored: Any, expected: NDArray[np.float64]) -> bool:
    """True unless ``stored`` is a list of numbers equal to ``expected`` (see CONSISTENCY_RTOL)."""
    try:
        got = np.asarray(stored, dtype=float)
    except (TypeError, ValueError):
        return True
    if got.shape != expected.shape or not np.all(np.isfinite(got)):
        return True
    scale = float(np.max(np.abs(expected))) if expected.size else 0.0
    return bool(np.any(np.abs(got - expected) > CONSISTENCY_RTOL * scale))


def expected_tf(
    controller: ControllerFile, entry: Mapping[str, Any]
) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """C(z) as one motor's gains give it: (num, den, what it was computed from).

    PI: C(z) = Kp + Ki·Ts·z/(z − 1), num = [Kp + Ki·Ts, −Kp], den = [1, −1]. Pole placement: the
    feedback from the measured speed to the voltage through the estimator, integrator and K
    (:func:`cartctl.design.loop.feedback_tf_coeffs`; Kr acts on the reference and is not in it).

    Raises
    ------
    KeyError, TypeError, ValueError
        The entry lacks a gain or holds something that is not a number.
    """
    ts = controller.period_s
    if controller.method == "pi":
        kp, ki = float(entry["kp"]), float(entry["ki"])
        num, den = pi_tf_coeffs(kp, ki, ts)
        return (
            num,
            den,
            f"Kp = {kp:.10g}, Ki = {ki:.10g} and Ts = {ts:g} s give (C(z) = Kp + Ki·Ts·z/(z−1))",
        )
    from cartctl.design.loop import feedback_tf_coeffs

    kalman = kalman_from_entry(entry["estimator"])
    gains = _Gains(
        np.asarray(entry["K"], dtype=float), float(entry["Ki"]), float(entry["Kr"]), ts, kalman
    )
    num, den = feedback_tf_coeffs(gains)  # type: ignore[arg-type]
    return num, den, f"K, Ki, the estimator and Ts = {ts:g} s give"


def consistency_problems(controller: ControllerFile) -> list[str]:
    """Where a file's stored C(z) disagrees with its gains, one sentence per key.

    A motor entry without ``controller_num``/``controller_den`` (pole-placement files of older
    cartctl) has nothing to disagree with; an entry whose gains are missing or not numbers is left
    to :func:`build_controllers`, which names the problem.
    """
    problems: list[str] = []
    for motor, entry in controller.motors.items():
        if "controller_num" not in entry and "controller_den" not in entry:
            continue
        try:
            num, den, source = expected_tf(controller, entry)
        except (KeyError, TypeError, ValueError, IndexError, np.linalg.LinAlgError):
            continue
        for key, expected in (("controller_num", num), ("controller_den", den)):
            stored = entry.get(key)
            if _disagrees(stored, expected):
                shown = _coeffs(stored) if isinstance(stored, list) else repr(stored)
                problems.append(
                    f"[motors.{motor}] {key} = {shown} but {source} {_coeffs(expected)}"
                )
    return problems


def make_estimator(
    design: KalmanDesign, gain: str
) -> KalmanSpeedEstimator | SteadyStateSpeedEstimator:
    """The runtime estimator for a design: filterpy ('kalman') or fixed gain ('steady-state')."""
    if gain == "kalman":
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
    if voltage_limit_v is not None:
        if not (math.isfinite(voltage_limit_v) and 0.0 < voltage_limit_v <= limit):
            raise InputError(
                f"voltage limit must be in (0, {limit:g}] V (the controller file's limit), got "
                f"{voltage_limit_v}"
            )
        limit = float(voltage_limit_v)
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
                    voltage_limit_v=limit,
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
