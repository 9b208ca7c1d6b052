"""Float-or-array arithmetic: a law written with Python's operators and these helpers runs on
plain floats (the loop's tick: no numpy call) and on arrays of shape (N,), one setting or plant
per element (``cartctl tune --robust``), with the same floating-point operations.
"""

from __future__ import annotations

import math
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

__all__ = ["all_true", "any_true", "clip", "is_finite", "larger", "select", "smaller"]

Value = TypeVar("Value", float, NDArray[np.float64])
"""A float, or an array of floats with one element per setting."""


def clip(value: Value, limit: float) -> Value:
    """``value`` limited to ±``limit``; NaN stays NaN."""
    if isinstance(value, np.ndarray):
        return np.minimum(limit, np.maximum(-limit, value))
    return limit if value > limit else (-limit if value < -limit else value)


def select(condition: object, if_true: Value, if_false: Value | float) -> Value:
    """``if_true`` where ``condition`` holds, else ``if_false`` (``np.where`` on arrays)."""
    if isinstance(condition, np.ndarray):
        return np.where(condition, if_true, if_false)  # type: ignore[return-value]
    fallback: Any = if_false  # a float where if_true is an array: np.where's broadcast
    return if_true if condition else fallback


def larger(a: Value, b: Value) -> Value:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.maximum(a, b)
    return a if a >= b else b


def smaller(a: Value, b: Value) -> Value:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.minimum(a, b)
    return a if a <= b else b


def is_finite(value: float | NDArray[np.float64]) -> bool | NDArray[np.bool_]:
    return np.isfinite(value) if isinstance(value, np.ndarray) else math.isfinite(value)


def any_true(condition: bool | NDArray[np.bool_]) -> bool:
    return bool(condition.any()) if isinstance(condition, np.ndarray) else bool(condition)


def all_true(condition: bool | NDArray[np.bool_]) -> bool:
    return bool(condition.all()) if isinstance(condition, np.ndarray) else bool(condition)
