"""Figures of merit of a model against data, and JSON-safe numbers (pure numpy)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray


def sum_squares(x: NDArray[np.float64]) -> float:
    """Σ x² in numpy's own loops: between scipy's QR calls a BLAS dot product left the two
    libraries' OpenBLAS threads fighting for the cores (3× slower on 2 cores)."""
    return float(np.einsum("i,i->", x, x))


def fit_from_norms(error_norm: float, spread: float) -> float:
    """The NRMSE fit (%) 100 · (1 − ‖y − ŷ‖ / ‖y − mean(y)‖) from the two norms; NaN for no
    spread (a constant y)."""
    if spread == 0.0:
        return float("nan")
    return float(100.0 * (1.0 - error_norm / spread))


def fit_percent(measured: ArrayLike, modelled: ArrayLike) -> float:
    """Normalised-RMSE fit (%): 100 · (1 − ‖y − ŷ‖ / ‖y − mean(y)‖); −inf when ``modelled`` is not
    finite throughout (a simulation that ran away), NaN for a constant ``measured``.

    100 % is perfect, 0 % no better than the mean, negative when worse. Used for simulation (ŷ from
    the input alone) and one-step prediction (ŷ from past measurements); callers label which."""
    y = np.asarray(measured, dtype=float)
    y_hat = np.asarray(modelled, dtype=float)
    if not np.isfinite(y_hat).all():
        return float("-inf")
    error, spread = np.ravel(y - y_hat), np.ravel(y - y.mean())  # any shape, as norm took
    return fit_from_norms(math.sqrt(sum_squares(error)), math.sqrt(sum_squares(spread)))


def finite_or_none(value: float | None) -> float | None:
    """``value`` as a float when finite; None for None, NaN and ±inf (JSON has neither)."""
    if value is None or not math.isfinite(value):
        return None
    return float(value)


def percentiles(values: ArrayLike) -> dict[str, float | None]:
    """The median, 99th percentile and largest of ``values`` (timing figures, µs) as ``p50``,
    ``p99`` and ``max``; None for each when there are no values."""
    x = np.asarray(values, dtype=np.float64)
    if not x.size:
        return {"p50": None, "p99": None, "max": None}
    p50, p99 = np.percentile(x, [50.0, 99.0])
    return {"p50": float(p50), "p99": float(p99), "max": float(x.max())}
