"""The diagnostics of one motor's identification: fits on validation data (``--validate-on``,
or the end of each experiment with ``--split``), residual tests, θ's covariance Σ with the Bode
bands it implies, and the order table.

Σ = σ̂² (ΦᵀΦ)⁻¹ for ARX, σ̂² (JᵀJ)⁻¹ for OE (J the simulation's Jacobian at θ̂). The bands draw
θ ~ N(θ̂, Σ) (seeded) and take per frequency the normal percentiles at ±1σ and ±2σ of the
magnitude (dB) and of the phase (deg, measured from the nominal model's so no draw jumps a turn).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import InputError
from cartctl.identification.arx import (
    ArxFit,
    Segment,
    as_segments,
    prediction_fit,
    simulation_fit,
    stacked_regression,
)
from cartctl.identification.etfe import model_response
from cartctl.identification.oe import simulation_error
from cartctl.identification.orders import OrderTable, order_table
from cartctl.identification.residuals import ResidualTest, prediction_residuals, residual_test
from cartctl.measures.metrics import finite_or_none
from cartctl.model import ArxModel

FitT = TypeVar("FitT", bound=ArxFit)

MIN_PART = 50
"""Fewest samples an estimation or validation part of a split may have."""

DRAWS = 1000
"""Number of θ draws per band."""

SEED = 0
"""Seed of the draws: the same data gives the same band."""

_PERCENTILES = (2.275, 15.866, 50.0, 84.134, 97.725)


def theta_covariance(
    fit: ArxFit, segments: Sequence[Segment], start: int | None = None
) -> NDArray[np.float64]:
    """Σ of θ̂ from the data the fit saw (``start``: the ARX fit's first row); NaN when singular."""
    m = fit.model
    data = as_segments(segments)
    if fit.method == "oe":
        err, jac = simulation_error(m.theta, data, m.na, m.nb, m.nk)
    else:
        jac, target = stacked_regression(data, m.na, m.nb, m.nk, start)
        err = target - jac @ m.theta
    n, d = jac.shape
    sigma2 = float(err @ err) / max(n - d, 1)
    r = np.linalg.qr(jac, mode="r")
    try:
        r_inv = np.linalg.solve(r, np.eye(d))
    except np.linalg.LinAlgError:
        return np.full((d, d), np.nan)
    return sigma2 * (r_inv @ r_inv.T)


@dataclass(frozen=True)
class BodeBand:
    """A model's Bode plot (dB re 1 rad/s/V, phase in deg unwrapped from low frequency) with the
    edges of its 1σ (row 0) and 2σ (row 1) bands, at ``freq_hz`` (Hz)."""

    freq_hz: NDArray[np.float64]
    mag_db: NDArray[np.float64]
    phase_deg: NDArray[np.float64]
    mag_db_lo: NDArray[np.float64]
    mag_db_hi: NDArray[np.float64]
    phase_deg_lo: NDArray[np.float64]
    phase_deg_hi: NDArray[np.float64]

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": f"sampling, {DRAWS} draws of θ ~ N(θ̂, Σ), seed {SEED}",
            "freq_hz": self.freq_hz.tolist(),
            "mag_db": self.mag_db.tolist(),
            "mag_db_1sigma": [self.mag_db_lo[0].tolist(), self.mag_db_hi[0].tolist()],
            "mag_db_2sigma": [self.mag_db_lo[1].tolist(), self.mag_db_hi[1].tolist()],
            "phase_deg": self.phase_deg.tolist(),
            "phase_deg_1sigma": [self.phase_deg_lo[0].tolist(), self.phase_deg_hi[0].tolist()],
            "phase_deg_2sigma": [self.phase_deg_lo[1].tolist(), self.phase_deg_hi[1].tolist()],
        }


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
    return BodeBand(
        freq_hz=f,
        mag_db=20.0 * np.log10(np.abs(h0)),
        phase_deg=phase0,
        mag_db_lo=mag_p[[1, 0]],
        mag_db_hi=mag_p[[3, 4]],
        phase_deg_lo=ph_p[[1, 0]],
        phase_deg_hi=ph_p[[3, 4]],
    )


def split_segments(
    segments: Sequence[Segment], fraction: float
) -> tuple[list[Segment], list[Segment]]:
    """Split each experiment: the first ``fraction`` of its samples estimate, the rest validate
    (each part at least :data:`MIN_PART` samples)."""
    if not 0.0 < fraction < 1.0:
        raise InputError(f"--split must be a fraction between 0 and 1 (e.g. 0.7), got {fraction:g}")
    est: list[Segment] = []
    val: list[Segment] = []
    for y_like, u_like in segments:
        y, u = np.asarray(y_like), np.asarray(u_like)
        n = len(y)
        m = round(fraction * n)
        if min(m, n - m) < MIN_PART:
            raise InputError(
                f"--split {fraction:g} leaves {m} estimation and {n - m} validation samples of "
                f"{n}; each part needs at least {MIN_PART}"
            )
        est.append((y[:m], u[:m]))
        val.append((y[m:], u[m:]))
    return est, val


def on_validation(fit: FitT, validation: Sequence[Segment]) -> FitT:
    """``fit`` with its simulation and prediction fits recomputed on the validation data."""
    return dataclasses.replace(
        fit,
        fit_simulation_percent=simulation_fit(fit.model, validation),
        fit_prediction_percent=prediction_fit(fit.model, validation),
    )


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
        out = {}
        for label, model in models.items():
            out[label] = {
                "fit_simulation_percent": finite_or_none(simulation_fit(model, data)),
                "fit_prediction_percent": finite_or_none(prediction_fit(model, data)),
                "dc_gain": finite_or_none(model.dc_gain()),
                "nk": model.nk,
                "theta": model.theta.tolist(),
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "fit_data": self.fit_on,
            "residuals": self.residuals.to_dict(),
            "theta_cov": self.theta_cov.tolist(),
            "bode_band": None if self.band is None else self.band.to_dict(),
        }
        if self.orders is not None:
            out["orders"] = self.orders.to_dict()
        return out


def diagnose(
    chosen: ArxFit,
    fitted: Sequence[Segment],
    *,
    start: int | None,
    raw: Sequence[Segment],
    validation: Sequence[Segment],
    period_s: float,
    orders_grid: dict[str, tuple[int, ...]] | None = None,
    order_data: Sequence[Segment] | None = None,
) -> Diagnostics:
    """The diagnostics of ``chosen``, fitted on ``fitted`` (from regression row ``start``, ARX);
    the order table (with ``orders_grid``) fitted on ``order_data`` (default ``fitted``)."""
    data = list(validation) or list(raw)
    y_all = np.concatenate([np.asarray(y, dtype=float) for y, _ in data])
    residuals = residual_test(
        prediction_residuals(chosen.model, data, chosen.method),
        output_rms=float(np.sqrt(np.mean(y_all**2))),
    )
    cov = theta_covariance(chosen, fitted, start if chosen.method == "arx" else None)
    nyquist = 0.5 / period_s
    band = bode_band(chosen.model, cov, np.geomspace(nyquist / 5000.0, 0.999 * nyquist, 60))
    orders = None
    if orders_grid is not None:
        orders = order_table(
            order_data if order_data is not None else fitted,
            orders_grid,
            period_s=period_s,
            eval_segments=raw,
            validation=list(validation) or None,
        )
    return Diagnostics(
        fit_on="validation" if validation else "estimation",
        residuals=residuals,
        theta_cov=cov,
        band=band,
        orders=orders,
        raw=list(raw),
        validation=list(validation),
    )
