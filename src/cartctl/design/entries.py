"""A controller file's tables, read back: the estimator and the gains.

:mod:`cartctl.design.controllerfile` loads a file through these checks and
:mod:`cartctl.design.build` turns the checked tables into runtime controllers. The check here: an
estimator whose arrays fit together and whose error decays (:func:`kalman_from_entry`); that a
stored ``controller_num``/``controller_den`` agrees with the gains is
:func:`cartctl.design.controller_ss.consistency_problems`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.runtime.kalman import KalmanDesign

_KALMAN_ARRAYS = ("A", "B", "C", "Q", "P", "L")


def kalman_from_entry(entry: Mapping[str, Any]) -> KalmanDesign:
    """Rebuild a :class:`KalmanDesign` from :func:`kalman_entry`'s table."""
    values: dict[str, Any] = {}
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
    Ki: float
    Kr: float
    period_s: float
    estimator: KalmanDesign


def feedback_gains(entry: Mapping[str, Any], period_s: float) -> _Gains:
    """A pole-placement ``[motors.X]`` entry's K, Ki, Kr and estimator.

    Raises
    ------
    KeyError, TypeError, ValueError
        The entry lacks a gain or holds something that is not a number.
    """
    kalman = kalman_from_entry(entry["estimator"])
    k = np.asarray(entry["K"], dtype=float).ravel()
    return _Gains(k, float(entry["Ki"]), float(entry["Kr"]), float(period_s), kalman)
