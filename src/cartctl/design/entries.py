"""A controller file's tables, read back: the estimator, the gains and their C(z) checked.

:mod:`cartctl.design.controllerfile` loads a file through these checks and
:mod:`cartctl.design.build` turns the checked tables into runtime controllers. The checks: an
estimator whose arrays fit together and whose error decays (:func:`kalman_from_entry`), and a
stored ``controller_num``/``controller_den`` that agrees with the gains
(:func:`consistency_problems`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.pi import pi_tf_coeffs
from cartctl.runtime.kalman import KalmanDesign

_KALMAN_ARRAYS = ("A", "B", "C", "Q", "P", "L")
CONSISTENCY_RTOL = 1e-6
"""How far a stored C(z) coefficient may be from the one its gains give, relative to the largest
coefficient of that polynomial (a file rounds nothing: the rest is floating-point noise)."""


def kalman_from_entry(entry: Mapping[str, Any]) -> KalmanDesign:
    """Rebuild a :class:`KalmanDesign` from :func:`kalman_entry`'s table."""
    values = {}
    for f in fields(KalmanDesign):
        if f.name not in entry:
            if f.default is not MISSING:  # a newer field (timing_noise_std_ticks): its default
                continue
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
    timing = values.get("timing_noise_std_ticks", 0.0)
    if (
        isinstance(timing, bool)
        or not isinstance(timing, int | float)
        or not (math.isfinite(timing) and 0.0 <= timing <= 10.0)
    ):
        raise ValueError(
            f"estimator.timing_noise_std_ticks must be a number of ticks in [0, 10], got {timing!r}"
        )
    error_dynamics = (np.eye(m) - np.outer(values["L"], values["C"])) @ A
    radius = float(np.max(np.abs(np.linalg.eigvals(error_dynamics))))
    if not radius < 1.0:
        raise ValueError(
            f"the estimator's error does not decay (its poles reach |z| = {radius:.4g}); "
            "redesign the controller"
        )


@dataclass(frozen=True)
class _Gains:
    """A :class:`~cartctl.runtime.statefeedback.FeedbackGains` rebuilt from a controller file."""

    K: NDArray[np.float64]
    K_xi: float
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
    controller: Any, entry: Mapping[str, Any]
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


def consistency_problems(controller: Any) -> list[str]:
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
