"""The diagnostics of one motor's identification: validation fits, residual tests, θ's
covariance with the Bode band it implies, and the order table.

Validation data is either an independent experiment (``identify --validate-on FILE``) or the end
of each estimation experiment (``--split F``: the first fraction F estimates, the rest
validates). With validation data the reported fits and the residual tests are on it; without, on
the raw estimation data.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import InputError
from cartctl.identification.arx import ArxFit, Segment, prediction_fit, simulation_fit
from cartctl.identification.bands import BodeBand, bode_band, theta_covariance
from cartctl.identification.orders import OrderTable, order_table
from cartctl.identification.residuals import ResidualTest, prediction_residuals, residual_test
from cartctl.measures.metrics import finite_or_none
from cartctl.model import ArxModel

__all__ = ["Diagnostics", "band_frequencies", "diagnose", "on_validation", "split_segments"]

FitT = TypeVar("FitT", bound=ArxFit)
"""An ARX fit or an output-error one: :func:`on_validation` keeps the kind."""

MIN_PART = 50
"""Fewest samples an estimation or validation part of a split may have."""


def split_segments(
    segments: Sequence[Segment], fraction: float
) -> tuple[list[Segment], list[Segment]]:
    """Split each experiment: the first ``fraction`` of its samples estimate, the rest validate.

    Raises
    ------
    InputError
        ``fraction`` outside (0, 1), or a part shorter than :data:`MIN_PART` samples.
    """
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


def band_frequencies(period_s: float, count: int = 60) -> NDArray[np.float64]:
    """Logarithmically spaced frequencies from 1/5000 of Nyquist to just below it (Hz)."""
    nyquist = 0.5 / period_s
    return np.geomspace(nyquist / 5000.0, 0.999 * nyquist, count)


@dataclass(frozen=True)
class Diagnostics:
    """What the diagnostics found for one motor.

    Attributes
    ----------
    fit_on : {'validation', 'estimation'}
        Which data the fits and residual tests are on.
    residuals : ResidualTest
        Of the chosen model.
    theta_cov : ndarray, shape (d, d)
        Σ of the chosen model's θ.
    band : BodeBand or None
        The chosen model's Bode plot with 1σ/2σ bands (None for a singular Σ).
    orders : OrderTable or None
        With ``--orders``.
    raw, validation : list of (y, u)
        The raw estimation data and the validation data (empty without), for fits of other
        models on the same data.
    """

    fit_on: str
    residuals: ResidualTest
    theta_cov: NDArray[np.float64]
    band: BodeBand | None
    orders: OrderTable | None
    raw: list[Segment]
    validation: list[Segment]

    def fit_data(self) -> list[Segment]:
        """The data fits are reported on."""
        return self.validation or self.raw

    def compared_fits(self, models: Mapping[str, ArxModel]) -> dict[str, dict[str, Any]]:
        """Fits (%) and DC gain of other models (``--compare``) on the same data as the fits."""
        data = self.fit_data()
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
        """Keys added to a motor's ``identify --json`` entry."""
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
    """Residual tests, Σ with its Bode band and, if asked for, the order table of one motor.

    Parameters
    ----------
    chosen : ArxFit
        The model the user asked for.
    fitted : sequence of (y, u)
        The data it was fitted on (for Σ); ``start`` its first regression row (ARX).
    raw : sequence of (y, u)
        Raw estimation data.
    validation : sequence of (y, u)
        Validation data, possibly empty.
    period_s : float
        Sample period (s).
    orders_grid : dict, optional
        The ``--orders`` grid.
    order_data : sequence of (y, u), optional
        Data for the order table's fits (default ``fitted``).
    """
    data = list(validation) or list(raw)
    y_all = np.concatenate([np.asarray(y, dtype=float) for y, _ in data])
    residuals = residual_test(
        prediction_residuals(chosen.model, data, chosen.method),
        output_rms=float(np.sqrt(np.mean(y_all**2))),
    )
    cov = theta_covariance(chosen, fitted, start if chosen.method == "arx" else None)
    band = bode_band(chosen.model, cov, band_frequencies(period_s))
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
