"""The diagnostics of one motor's identification: residual tests, θ's covariance Σ with its
Bode bands, and the order table, on validation data when there is any; docs/identification.md
says what they mean.

Σ = σ̂² (ΦᵀΦ)⁻¹ for ARX, σ̂² (JᵀJ)⁻¹ for OE (J the simulation's Jacobian at θ̂), the fit's own
(on the data it was fitted on: θ_std is √diag Σ); the bands draw
θ ~ N(θ̂, Σ) (seeded) and take per frequency the normal percentiles at ±1σ and ±2σ of the
magnitude (dB) and of the phase (deg, from the nominal model's so no draw jumps a turn).

Residual tests, as MATLAB's ``resid``, on the one-step prediction residuals ε (ARX's equation
error, OE's simulation error), each experiment's mean removed, summed over experiments (N):

    r_ε(τ)  = Σ ε(k) ε(k+τ) / Σ ε(k)²,               τ = 1 … M
    r_εu(τ) = Σ ε(k+τ) u(k) / √(Σ ε(k)² Σ u(k)²),     τ = −M … M

with 99 % bounds 2.58 / √N and Ljung's 2.58 √(max(P, 1) / N), P = Σ_{|τ| ≤ M} r_ε(τ) r_u(τ)
floored at its white value 1. A test passes with no more lags outside than a white, independent
residual exceeds with 5 % probability (binomial, 1 % a lag).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from cartctl.errors import InputError
from cartctl.identification.arx import (
    ArxFit,
    Checked,
    Segment,
    as_segments,
    first_row,
    prediction_fit,
    simulation_fit,
    stacked_regression,
)
from cartctl.identification.etfe import model_response
from cartctl.identification.orders import OrderTable
from cartctl.measures.metrics import finite_or_none
from cartctl.model import ArxModel

Z_99 = 2.576  # two-sided 99 % point of the standard normal distribution

MAX_LAGS = 25  # lags of the autocorrelation (1 … 25) and cross-correlation (−25 … 25), as ``resid``

FALSE_ALARM = 0.05  # probability with which a white, independent residual may still fail a test


def prediction_residuals(
    model: ArxModel, segments: Sequence[Segment], method: str = "arx"
) -> list[Checked]:
    """One-step prediction residuals ε (rad/s) with their inputs u (V), per experiment: 'arx'
    from the first row with all regressors inside (shorter experiments left out), 'oe' the
    simulation error from rest."""
    start = first_row(model.na, model.nb, model.nk)
    out = []
    for y, u in as_segments(segments):
        if method == "oe":
            out.append((y - model.simulate(u), u))
        elif y.size > start:
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
        out: dict[str, Any] = {}
        for kind in ("auto", "cross"):
            r = getattr(self, kind)
            out[f"{kind}_outside"] = getattr(self, f"{kind}_outside")
            out[f"{kind}_lags"] = int(r.size)
            out[f"{kind}_allowed"] = getattr(self, f"{kind}_allowed")
            out[f"{kind}_max_abs"] = float(np.max(np.abs(r)))
        scalars = ("bound_99", "cross_bound_99", "cross_variance", "n_samples", "rms_rad_s")
        flags = ("negligible", "white", "independent")
        out |= {k: getattr(self, k) for k in (*scalars, *flags)}
        return out | {"auto": self.auto.tolist(), "cross": self.cross.tolist()}

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
    r_u = _correlation([(u, u) for _, u in centred], np.arange(0, m + 1))
    p = float(r_u[0] + 2.0 * np.sum(auto * r_u[1:]))  # r_ε(0) = 1
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


DRAWS = 1000  # number of θ draws per band

SEED = 0  # seed of the draws: the same data gives the same band

_PERCENTILES = (2.275, 15.866, 50.0, 84.134, 97.725)


@dataclass(frozen=True)
class BodeBand:
    """A model's Bode plot (dB re 1 rad/s/V, phase in deg unwrapped from low frequency) at
    ``freq_hz`` (Hz), with ``*_bands[k]`` the (low, high) edges of its (k + 1)σ band."""

    freq_hz: NDArray[np.float64]
    mag_db: NDArray[np.float64]
    phase_deg: NDArray[np.float64]
    mag_db_bands: NDArray[np.float64]
    phase_deg_bands: NDArray[np.float64]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"method": f"sampling, {DRAWS} draws of θ ~ N(θ̂, Σ), seed {SEED}"}
        out["freq_hz"] = self.freq_hz.tolist()
        for q in ("mag_db", "phase_deg"):
            out[q] = getattr(self, q).tolist()
            out |= {f"{q}_{k + 1}sigma": getattr(self, f"{q}_bands")[k].tolist() for k in (0, 1)}
        return out


def bode_band(
    model: ArxModel, cov: NDArray[np.float64], freq_hz: NDArray[np.float64]
) -> BodeBand | None:
    """The 1σ and 2σ Bode bands of ``model`` from θ's covariance; None when it is not finite."""
    f = np.asarray(freq_hz, dtype=float)
    if not np.all(np.isfinite(cov)):
        return None
    rng = np.random.default_rng(SEED)
    thetas = rng.multivariate_normal(model.theta, cov, size=DRAWS, method="eigh")
    z = np.exp(2j * np.pi * f * model.period_s)
    h0 = model_response(model, f)
    na = model.na
    # H = z^-nk B(z^-1) / A(z^-1): evaluate in powers of z^-1 for every draw at once
    zi = 1.0 / z
    a_pow = zi[None, :] ** np.arange(1, na + 1)[:, None]  # (na, m)
    b_pow = zi[None, :] ** (model.nk + np.arange(model.nb))[:, None]  # (nb, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = (thetas[:, na:] @ b_pow) / (1.0 + thetas[:, :na] @ a_pow)
        mag = 20.0 * np.log10(np.abs(h))
        dphase = np.degrees(np.angle(h / h0[None, :]))
    phase0 = np.degrees(np.unwrap(np.angle(h0)))
    mag_p = np.nanpercentile(mag, _PERCENTILES, axis=0)
    ph_p = np.nanpercentile(dphase, _PERCENTILES, axis=0) + phase0[None, :]
    edges = [[1, 3], [0, 4]]  # the percentiles of the 1σ and the 2σ band
    return BodeBand(f, 20.0 * np.log10(np.abs(h0)), phase0, mag_p[edges], ph_p[edges])


@dataclass(frozen=True)
class Diagnostics:
    """One motor's diagnostics: the data the fits and residual tests are on ('validation' or
    'estimation'), the chosen model's residual tests, Σ and Bode band (None for a singular Σ), the
    order table, and the raw and validation data for fits of other models on the same data."""

    fit_on: str
    residuals: ResidualTest
    theta_cov: NDArray[np.float64]
    band: BodeBand | None
    orders: OrderTable | None
    raw: list[Segment]
    validation: list[Segment]

    def compared_fits(self, models: Mapping[str, ArxModel]) -> dict[str, dict[str, Any]]:
        """Fits (%) and DC gain of other models (``--compare``) on the same data as the fits."""
        data = self.validation or self.raw
        return {
            label: {
                "fit_simulation_percent": finite_or_none(simulation_fit(model, data)),
                "fit_prediction_percent": finite_or_none(prediction_fit(model, data)),
                "dc_gain": finite_or_none(model.dc_gain()),
                "nk": model.nk,
                "theta": model.theta.tolist(),
            }
            for label, model in models.items()
        }

    def to_dict(self) -> dict[str, Any]:
        band = None if self.band is None else self.band.to_dict()
        out: dict[str, Any] = {"fit_data": self.fit_on, "residuals": self.residuals.to_dict()}
        out |= {"theta_cov": self.theta_cov.tolist(), "bode_band": band}
        return out if self.orders is None else out | {"orders": self.orders.to_dict()}


def diagnose(
    chosen: ArxFit,
    raw: Sequence[Segment],
    validation: Sequence[Segment],
    orders: OrderTable | None,
) -> Diagnostics:
    """The diagnostics of ``chosen`` (its Σ its own) on ``validation`` or else the ``raw`` data;
    ``orders`` the order table, if asked for."""
    data = list(validation) or list(raw)
    y_all = np.concatenate([np.asarray(y, dtype=float) for y, _ in data])
    residuals = residual_test(
        prediction_residuals(chosen.model, data, chosen.method),
        output_rms=float(np.sqrt(np.mean(y_all**2))),
    )
    cov = chosen.theta_cov
    nyquist = 0.5 / chosen.model.period_s
    band = bode_band(chosen.model, cov, np.geomspace(nyquist / 5000.0, 0.999 * nyquist, 60))
    fit_on = "validation" if validation else "estimation"
    return Diagnostics(fit_on, residuals, cov, band, orders, list(raw), list(validation))
