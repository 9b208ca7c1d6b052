"""Residual tests of an identified model, as MATLAB's ``resid`` (docs/identification.md says
what they mean). On the one-step prediction residuals ε (the equation error for ARX, the
simulation error for OE) with each experiment's mean removed, summed over experiments (N samples):

    r_ε(τ)  = Σ ε(k) ε(k+τ) / Σ ε(k)²,                        τ = 1 … M
    r_εu(τ) = Σ ε(k+τ) u(k) / √(Σ ε(k)² Σ u(k)²),              τ = −M … M

99 % bounds: 2.58 / √N for r_ε, Ljung's 2.58 √(max(P, 1) / N) for r_εu with
P = Σ_{|τ| ≤ M} r_ε(τ) r_u(τ) (floored at its white-residual value 1: the truncated estimate can
collapse). A test passes with no more lags outside than a white, independent residual exceeds
with 5 % probability (binomial over the lags at 1 % each).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from cartctl.errors import InputError
from cartctl.identification.arx import Checked, Segment, as_segments, first_row, stacked_regression
from cartctl.model import ArxModel

Z_99 = 2.576
"""Two-sided 99 % point of the standard normal distribution."""

MAX_LAGS = 25
"""Lags of the autocorrelation (1 … 25) and cross-correlation (−25 … 25), as ``resid``."""

FALSE_ALARM = 0.05
"""Probability with which a white, independent residual may still fail a test."""


def prediction_residuals(
    model: ArxModel, segments: Sequence[Segment], method: str = "arx"
) -> list[Checked]:
    """One-step prediction residuals ε (rad/s) with their inputs u (V), per experiment: 'arx'
    from the first row with all regressors inside (shorter experiments left out), 'oe' the
    simulation error from rest."""
    out = []
    for y, u in as_segments(segments):
        if method == "oe":
            out.append((y - model.simulate(u), u))
            continue
        start = first_row(model.na, model.nb, model.nk)
        if y.size <= start:
            continue
        phi, target = stacked_regression([(y, u)], model.na, model.nb, model.nk, start)
        out.append((target - phi @ model.theta, u[start:].copy()))
    return out


@dataclass(frozen=True)
class ResidualTest:
    """r_ε at lags 1 … M and r_εu at −M … M with their 99 % bounds; ``cross_variance`` is P
    before the floor, ``*_allowed`` the most lags outside that pass, ``negligible`` residuals
    below 1e-6 of the output's RMS (rounding, about which the tests say nothing)."""

    auto_lags: NDArray[np.int_]
    auto: NDArray[np.float64]
    cross_lags: NDArray[np.int_]
    cross: NDArray[np.float64]
    bound_99: float
    cross_bound_99: float
    n_samples: int
    auto_allowed: int
    cross_allowed: int
    rms_rad_s: float = 0.0
    negligible: bool = False
    cross_variance: float = 1.0

    @property
    def auto_outside(self) -> int:
        return int(np.count_nonzero(np.abs(self.auto) > self.bound_99))

    @property
    def cross_outside(self) -> int:
        return int(np.count_nonzero(np.abs(self.cross) > self.cross_bound_99))

    @property
    def white(self) -> bool:
        return self.auto_outside <= self.auto_allowed

    @property
    def independent(self) -> bool:
        return self.cross_outside <= self.cross_allowed

    def to_dict(self) -> dict[str, Any]:
        return {
            "auto_outside": self.auto_outside,
            "auto_lags": int(self.auto_lags.size),
            "auto_allowed": self.auto_allowed,
            "auto_max_abs": float(np.max(np.abs(self.auto))),
            "cross_outside": self.cross_outside,
            "cross_lags": int(self.cross_lags.size),
            "cross_allowed": self.cross_allowed,
            "cross_max_abs": float(np.max(np.abs(self.cross))),
            "bound_99": self.bound_99,
            "cross_bound_99": self.cross_bound_99,
            "cross_variance": self.cross_variance,
            "n_samples": self.n_samples,
            "rms_rad_s": self.rms_rad_s,
            "negligible": self.negligible,
            "white": self.white,
            "independent": self.independent,
            "auto": self.auto.tolist(),
            "cross": self.cross.tolist(),
        }

    def summary(self) -> str:
        """One line for the terminal."""
        auto = "white" if self.white else "NOT white"
        cross = "independent of the input" if self.independent else "CORRELATED with the input"
        if self.negligible:
            return (
                "residuals: RMS below 1e-6 of the output's, the rounding of an exact fit, about "
                "which the residual tests say nothing"
            )
        return (
            f"residuals (99 % bounds, N = {self.n_samples}): autocorrelation "
            f"{self.auto_outside}/{self.auto_lags.size} lags outside ±{self.bound_99:.3f}, "
            f"max |r| {np.max(np.abs(self.auto)):.3f}: {auto}; cross-correlation "
            f"{self.cross_outside}/{self.cross_lags.size} outside ±{self.cross_bound_99:.3f}, "
            f"max |r| {np.max(np.abs(self.cross)):.3f}: {cross}"
        )


def _lagged_sum(a: NDArray[np.float64], b: NDArray[np.float64], lag: int) -> float:
    """Σ_k a(k + lag) b(k) where both exist (einsum: no BLAS threads)."""
    n = a.size
    if abs(lag) >= n:
        return 0.0
    if lag >= 0:
        return float(np.einsum("i,i->", a[lag:], b[: n - lag]))
    return float(np.einsum("i,i->", a[: n + lag], b[-lag:]))


def _correlation(pairs: Sequence[Checked], lags: NDArray[np.int_]) -> NDArray[np.float64]:
    """Σ over experiments of Σ_k a(k+τ) b(k), normalised by √(Σ a² Σ b²)."""
    num = np.array([sum(_lagged_sum(a, b, int(t)) for a, b in pairs) for t in lags])
    energy_a = sum(float(np.einsum("i,i->", a, a)) for a, _ in pairs)
    energy_b = sum(float(np.einsum("i,i->", b, b)) for _, b in pairs)
    if energy_a == 0.0 or energy_b == 0.0:
        return np.zeros(lags.size)
    return num / np.sqrt(energy_a * energy_b)


def residual_test(
    residuals: Sequence[Checked], max_lags: int = MAX_LAGS, output_rms: float | None = None
) -> ResidualTest:
    """Whiteness and independence tests of (ε, u) per experiment, M = ``max_lags`` lowered to a
    quarter of the samples; refuses fewer than 20 samples."""
    centred = [(e - e.mean(), u - u.mean()) for e, u in residuals if e.size]
    n = sum(e.size for e, _ in centred)
    if n < 20:
        raise InputError(f"too few residual samples for the residual tests: {n}, need at least 20")
    m = max(1, min(int(max_lags), n // 4))
    auto_lags = np.arange(1, m + 1)
    cross_lags = np.arange(-m, m + 1)
    auto = _correlation([(e, e) for e, _ in centred], auto_lags)
    cross = _correlation(centred, cross_lags)
    r_e = np.concatenate([[1.0], auto])
    r_u = _correlation([(u, u) for _, u in centred], np.arange(0, m + 1))
    p = float(r_e[0] * r_u[0] + 2.0 * np.sum(r_e[1:] * r_u[1:]))
    rms = float(np.sqrt(sum(float(np.einsum("i,i->", e, e)) for e, _ in centred) / n))
    return ResidualTest(
        auto_lags=auto_lags,
        auto=auto,
        cross_lags=cross_lags,
        cross=cross,
        bound_99=Z_99 / np.sqrt(n),
        cross_bound_99=Z_99 * np.sqrt(max(p, 1.0) / n),
        n_samples=n,
        auto_allowed=int(stats.binom.ppf(1.0 - FALSE_ALARM, auto_lags.size, 0.01)),
        cross_allowed=int(stats.binom.ppf(1.0 - FALSE_ALARM, cross_lags.size, 0.01)),
        rms_rad_s=rms,
        negligible=output_rms is not None and rms < 1e-6 * output_rms,
        cross_variance=p,
    )
