"""Figures of merit shared by identification, design and run review (pure numpy)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike


def fit_percent(measured: ArrayLike, modelled: ArrayLike) -> float:
    """Normalised-RMSE fit in percent: 100 · (1 − ‖y − ŷ‖ / ‖y − mean(y)‖).

    100 % is a perfect fit, 0 % is no better than the mean, and it is negative when worse.
    Used both for simulation (ŷ simulated from the input alone) and for one-step prediction
    (ŷ predicted from past measurements); callers label which.

    Parameters
    ----------
    measured, modelled : array_like, shape (n,)
        Measured and modelled output, same units.

    Returns
    -------
    float
        The fit (%); NaN when the measured output is constant.
    """
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
