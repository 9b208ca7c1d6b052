"""θ's covariance and the confidence bands it puts on a model's Bode plot.

Covariance, as the fits compute their standard deviations (the same σ̂ and normal matrix, here
kept whole):

- ARX: Σ = σ̂² (ΦᵀΦ)⁻¹, Φ the regressors of the fitted data, σ̂² = ‖y − Φθ̂‖² / (N − d);
- OE: Σ = σ̂² (JᵀJ)⁻¹, J the Jacobian of the simulation at θ̂, σ̂² the simulation error's.

Bands are propagated by sampling: θ ~ N(θ̂, Σ) from a seeded generator, the frequency response
of each draw, and per frequency the percentiles that a normal distribution has at ±1σ
(15.9 %, 84.1 %) and ±2σ (2.3 %, 97.7 %), of the magnitude (dB) and of the phase (degrees,
measured from the nominal model's so no draw jumps a turn).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.identification.arx import ArxFit, Segment, as_segments, stacked_regression
from cartctl.identification.etfe import model_response
from cartctl.identification.oe import _simulate_with_jacobian
from cartctl.model import ArxModel

__all__ = ["BodeBand", "bode_band", "theta_covariance"]

DRAWS = 1000
"""Number of θ draws per band."""

SEED = 0
"""Seed of the draws: the same data gives the same band."""

_PERCENTILES = (2.275, 15.866, 50.0, 84.134, 97.725)


def theta_covariance(
    fit: ArxFit, segments: Sequence[Segment], start: int | None = None
) -> NDArray[np.float64]:
    """Σ of θ̂ (see the module docstring), from the data the fit was made on.

    Parameters
    ----------
    fit : ArxFit
        An ARX or OE fit.
    segments : sequence of (y, u)
        The fitted data (prefiltered, averaged, as the fit saw it).
    start : int, optional
        The ARX fit's first regression row (default: the first with all regressors inside).

    Returns
    -------
    ndarray, shape (d, d)
        NaN everywhere when the normal matrix is singular.
    """
    m = fit.model
    data = as_segments(segments)
    if fit.method == "oe":
        parts = [_simulate_with_jacobian(m.theta, u, m.na, m.nb, m.nk) for _, u in data]
        jac = np.concatenate([j for _, j in parts])
        err = np.concatenate([y - y_hat for (y, _), (y_hat, _) in zip(data, parts, strict=True)])
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
    """A model's Bode plot with its 1σ and 2σ bands.

    Attributes
    ----------
    freq_hz : ndarray, shape (m,)
    mag_db : ndarray, shape (m,)
        The nominal model's magnitude (dB re 1 rad/s/V).
    phase_deg : ndarray, shape (m,)
        The nominal model's phase, unwrapped from low frequency (deg).
    mag_db_lo, mag_db_hi : ndarray, shape (2, m)
        Lower and upper edges of the 1σ (row 0) and 2σ (row 1) magnitude bands (dB).
    phase_deg_lo, phase_deg_hi : ndarray, shape (2, m)
        The same for the phase (deg).
    """

    freq_hz: NDArray[np.float64]
    mag_db: NDArray[np.float64]
    phase_deg: NDArray[np.float64]
    mag_db_lo: NDArray[np.float64]
    mag_db_hi: NDArray[np.float64]
    phase_deg_lo: NDArray[np.float64]
    phase_deg_hi: NDArray[np.float64]

    def to_dict(self) -> dict[str, Any]:
        """The ``bode_band`` entry of ``identify --json``."""
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
    """The 1σ and 2σ Bode bands of ``model`` from θ's covariance ``cov`` (module docstring).

    Returns None when ``cov`` is not finite.
    """
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
