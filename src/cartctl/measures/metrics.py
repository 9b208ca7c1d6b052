"""Figures of merit of a model against data, and JSON-safe numbers (pure numpy)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike


def fit_percent(measured: ArrayLike, modelled: ArrayLike) -> float:
    """Normalised-RMSE fit (%): 100 · (1 − ‖y − ŷ‖ / ‖y − mean(y)‖); NaN for a constant
    ``measured``.

    100 % is perfect, 0 % no better than the mean, negative when worse. Used for simulation (ŷ from
    the input alone) and one-step prediction (ŷ from past measurements); callers label which."""
    y = np.asarray(measured, dtype=float)
    y_hat = np.asarray(modelled, dtype=float)
    spread = np.linalg.norm(y - y.mean())
    if spread == 0.0:
        return float("nan")
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / spread))


def finite_or_none(value: float | None) -> float | None:
    """``value`` as a float when finite; None for None, NaN and ±inf (JSON has neither)."""
    if value is None or not math.isfinite(value):
        return None
    return float(value)
