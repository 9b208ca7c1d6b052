"""Output-error refinement of an ARX estimate (docs/identification.md): minimise

    V(θ) = Σ_k (y[k] − ŷ(k, θ))²,     ŷ = B(q) q⁻ⁿᵏ / A(q) u    (simulated from rest),

unbiased for white measurement noise where ARX's equation error is not, by
scipy.optimize.least_squares with the exact Jacobian ∂ŷ/∂a_i = −q⁻ⁱ ŷ / A(q),
∂ŷ/∂b_j = q⁻⁽ⁿᵏ⁺ʲ⁾ u / A(q). A(q) is searched through reflection coefficients k_i = tanh(η_i)
(Levinson step-up, every root inside the unit circle) scaled by ρ (a_i = ã_i ρⁱ), so every trial
model has its poles inside |z| ≤ ρ; a start beyond ρ is projected inside first. The simulation
fit on the unfiltered data decides, so the result is never worse than its start.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, signal

from cartctl.errors import InputError
from cartctl.identification.arx import (
    ArxFit,
    Checked,
    IdentificationError,
    Segment,
    as_segments,
    first_row,
    rows_from,
    simulation_fit,
    theta_covariance,
)
from cartctl.measures.metrics import finite_or_none
from cartctl.model import MARGINAL_POLE_RADIUS, ArxModel

MAX_OE_PARAMETERS = 10
"""The most na + nb an output-error refinement takes: measured on a minute of data, one core,
4 parameters take 0.2 s, 10 take 4 s, 20 take 33 s. A DC motor needs 2 + 2."""

POLE_BOUND = MARGINAL_POLE_RADIUS
"""Largest pole magnitude |z| an output-error model may have (ρ, 0.99): beyond it is marginal."""

_PROJECT_MARGIN = 0.01
"""A start's poles beyond ρ are pulled in to ρ − this, where tanh is not saturated."""

_ACTIVE_TOL = 1e-3  # the bound counts as active when the largest pole is within this of ρ

_COMPLEX_STEP = 1e-20


@dataclass(frozen=True)
class OeFit(ArxFit):
    """An output-error fit with what the safeguards did: the bound ρ and whether the largest
    pole sits on it, whether the start was kept (nothing beat it) or projected inside ρ, the
    start's simulation fit (%), and one note per safeguard that acted."""

    pole_bound: float = POLE_BOUND
    pole_bound_active: bool = False
    start_kept: bool = False
    start_projected: bool = False
    start_fit_simulation_percent: float = math.nan
    notes: tuple[str, ...] = ()

    def on(self, segments: Sequence[Segment]) -> OeFit:
        """As :meth:`ArxFit.on`; the prediction fit is the simulation's (an OE predictor simulates)."""
        fit = super().on(segments)
        return replace(fit, fit_prediction_percent=fit.fit_simulation_percent)

    def to_dict(self) -> dict[str, Any]:
        own = [f.name for f in fields(self) if f.name not in ArxFit.__dataclass_fields__]
        out = super().to_dict() | {name: getattr(self, name) for name in own}
        start_fit = finite_or_none(self.start_fit_simulation_percent)
        return out | {"start_fit_simulation_percent": start_fit, "notes": list(self.notes)}


def _shift(x: NDArray[np.float64], lag: int) -> NDArray[np.float64]:
    out = np.zeros_like(x)
    out[lag:] = x[: x.size - lag]
    return out


def simulation_error(
    theta: NDArray[np.float64], data: Sequence[Checked], na: int, nb: int, nk: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """y − ŷ of every experiment simulated from rest, stacked, and the Jacobian ∂ŷ/∂θ."""
    a = np.concatenate([[1.0], theta[:na]])
    b = np.concatenate([np.zeros(nk), theta[na:]])
    errors, jacobians = [], []
    for y, u in data:
        y_hat = signal.lfilter(b, a, u)
        w = signal.lfilter([1.0], a, y_hat)
        v = signal.lfilter([1.0], a, u)
        jac = np.empty((u.size, na + nb))
        for i in range(na):
            jac[:, i] = -_shift(w, i + 1)
        for j in range(nb):
            jac[:, na + j] = _shift(v, nk + j)
        errors.append(y - y_hat)
        jacobians.append(jac)
    return np.concatenate(errors), np.concatenate(jacobians)


def _step_up(eta: NDArray[Any], rho: float) -> NDArray[Any]:
    """a_1 … a_na with every root inside |z| < ρ, from unconstrained η (real or complex-stepped)."""
    poly = np.ones(1, dtype=eta.dtype)
    for k in np.tanh(eta):
        poly = np.concatenate([poly, [0.0]]) + k * np.concatenate([[0.0], poly[::-1]])
    return poly[1:] * rho ** np.arange(1, eta.size + 1)


def _step_down(ar: NDArray[np.float64], rho: float) -> NDArray[np.float64] | None:
    """η of a_1 … a_na (the inverse of :func:`_step_up`); None when a root is not inside ρ."""
    poly = np.concatenate([[1.0], ar / rho ** np.arange(1, ar.size + 1)])
    eta = np.empty(ar.size)
    for m in range(ar.size, 0, -1):
        k = poly[m]
        if not abs(k) < 1.0 - 1e-12:
            return None
        eta[m - 1] = np.arctanh(k)
        poly = (poly[:m] - k * poly[m:0:-1]) / (1.0 - k * k)
    return eta


def _d_ar_d_eta(eta: NDArray[np.float64], rho: float) -> NDArray[np.float64]:
    """∂(a_1 … a_na)/∂η, shape (na, na), by a complex step."""
    steps = eta.astype(complex) + 1j * _COMPLEX_STEP * np.eye(eta.size)  # row j: η_j stepped
    return np.array([_step_up(step, rho).imag / _COMPLEX_STEP for step in steps]).T


def project_poles(ar: Sequence[float] | NDArray[np.float64], radius: float) -> NDArray[np.float64]:
    """a_1 … a_na with every root beyond ``radius`` pulled in to it (angles kept, so
    conjugate pairs move together and the coefficients stay real)."""
    roots = np.roots(np.concatenate([[1.0], np.asarray(ar, dtype=float)]))
    mags = np.abs(roots)
    scale = np.where(mags > radius, radius / np.maximum(mags, 1e-300), 1.0)
    return np.real(np.poly(roots * scale))[1:]


def _refit_b(
    ar: NDArray[np.float64], data: Sequence[Checked], nb: int, nk: int
) -> NDArray[np.float64]:
    """B minimising the simulation error with A fixed: ŷ is linear in B, its columns of the
    Jacobian (which do not depend on B) the regressors."""
    jac = simulation_error(np.concatenate([ar, np.zeros(nb)]), data, ar.size, nb, nk)[1]
    target = np.concatenate([y for y, _ in data])
    return np.linalg.lstsq(jac[:, ar.size :], target, rcond=None)[0]


def _refine(
    start: NDArray[np.float64], data: Sequence[Checked], na: int, nk: int, rho: float, evals: int
) -> NDArray[np.float64]:
    """θ minimising the simulation error on ``data`` over poles inside ρ, from θ ``start``, with
    at most ``evals`` evaluations."""
    nb = start.size - na
    if na == 0:  # an FIR model: ŷ is linear in B, its least squares is the optimum
        return _refit_b(start[:0], data, nb, nk)
    eta0 = _step_down(start[:na], rho)
    if eta0 is None:  # a start on the bound itself: from just inside
        eta0 = _step_down(project_poles(start[:na], rho - _PROJECT_MARGIN), rho)
    if eta0 is None:
        raise IdentificationError(f"cannot start the output-error search from a = {start[:na]}")

    def theta_of(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([_step_up(x[:na], rho), x[na:]])

    def residual(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return simulation_error(theta_of(x), data, na, nb, nk)[0]

    def jacobian(x: NDArray[np.float64]) -> NDArray[np.float64]:
        jac = -simulation_error(theta_of(x), data, na, nb, nk)[1]
        jac[:, :na] = jac[:, :na] @ _d_ar_d_eta(x[:na], rho)
        return jac

    x0 = np.concatenate([eta0, start[na:]])
    result = optimize.least_squares(
        residual, x0, jac=jacobian, method="trf", x_scale="jac", max_nfev=evals
    )
    return theta_of(result.x)


def check_oe_orders(na: int, nb: int) -> None:
    """Refuse na + nb above :data:`MAX_OE_PARAMETERS`, naming the options."""
    if na + nb > MAX_OE_PARAMETERS:
        raise InputError(
            f"--method oe takes na + nb up to {MAX_OE_PARAMETERS} (its refinement simulates the "
            f"model for every parameter), got --na {na} --nb {nb}; use --method arx for these "
            "orders"
        )


def fit_oe(
    segments: Sequence[Segment],
    initial: ArxModel,
    *,
    max_evaluations: int = 200,
    eval_segments: Sequence[Segment] | None = None,
    pole_bound: float = POLE_BOUND,
) -> OeFit:
    """Refine ``initial`` (orders and delay kept) by output-error least squares on ``segments``.

    ``eval_segments`` (default ``segments``; the unfiltered data when those are prefiltered) decide
    by simulation fit; every pole ends inside ``pole_bound``; Σ, σ̂² (JᵀJ)⁻¹
    (:func:`~cartctl.identification.arx.theta_covariance`), and the prediction fit are on the data
    the chosen θ was refined on.
    """
    if max_evaluations < 1:
        raise InputError(f"max_evaluations must be at least 1, got {max_evaluations}")
    check_oe_orders(initial.na, initial.nb)
    if not 0.0 < pole_bound <= 1.0:
        raise InputError(f"pole_bound must be in (0, 1], got {pole_bound}")
    data = as_segments(segments)
    evaluation = data if eval_segments is None else as_segments(eval_segments)
    na, nb, nk, ts = initial.na, initial.nb, initial.nk, initial.period_s
    rows_from(data, first_row(na, nb, nk))
    rho = float(pole_bound)

    def model_of(theta: NDArray[np.float64]) -> ArxModel:
        return ArxModel.from_theta(theta, na=na, nb=nb, nk=nk, period_s=ts)

    def fit_of(theta: NDArray[np.float64]) -> float:
        value = simulation_fit(model_of(theta), evaluation)
        return value if math.isfinite(value) else -math.inf

    start = np.asarray(initial.theta, dtype=float)
    start_fit = fit_of(start)
    notes = []
    projected = na > 0 and initial.pole_radius() > rho
    if projected:
        ar = project_poles(start[:na], rho - _PROJECT_MARGIN)
        start = np.concatenate([ar, _refit_b(ar, data, nb, nk)])
        notes.append(
            f"the ARX start has a pole at |z| = {initial.pole_radius():.4f}, beyond the bound "
            f"{rho:g}: projected inside (|z| ≤ {rho - _PROJECT_MARGIN:g}) before refining"
        )
    candidates = [("start", start), ("refined", _refine(start, data, na, nk, rho, max_evaluations))]
    if na > 0 and eval_segments is not None and eval_segments is not segments:
        refined = _refine(start, evaluation, na, nk, rho, max_evaluations)
        candidates.append(("refined on eval", refined))
    fits = [fit_of(theta) for _, theta in candidates]
    best = max(range(len(candidates)), key=lambda i: (fits[i], i > 0))
    label, theta = candidates[best]
    kept = label == "start"
    if kept:
        notes.append(
            f"no refinement improved the start's simulation fit ({fits[0]:.2f} %, refined "
            f"{max(fits[1:]):.2f} %): the start is returned"
        )
    elif label == "refined on eval":
        notes.append(
            f"refined on the unfiltered data ({fits[best]:.2f} %): the prefiltered criterion's "
            f"optimum fits it less ({fits[1]:.2f} %)"
        )
    model = model_of(theta)
    radius = model.pole_radius()
    active = na > 0 and radius >= rho - _ACTIVE_TOL
    if active:
        notes.append(
            f"the pole bound |z| ≤ {rho:g} is active (largest pole |z| = {radius:.4f}): the "
            "data pull a pole further out"
        )
    fit_data = evaluation if label == "refined on eval" else data
    err, jac = simulation_error(theta, fit_data, na, nb, nk)
    n = jac.shape[0]
    return OeFit(
        model=model,
        theta_cov=theta_covariance(np.linalg.qr(jac, mode="r"), float(err @ err), n),
        fit_simulation_percent=simulation_fit(model, evaluation),
        fit_prediction_percent=simulation_fit(model, fit_data),  # an OE predictor simulates
        residual_rms=float(np.sqrt(np.mean(err**2))),
        n_samples=int(n),
        method="oe",
        pole_bound=rho,
        pole_bound_active=bool(active),
        start_kept=kept,
        start_projected=bool(projected),
        start_fit_simulation_percent=start_fit,
        notes=tuple(notes),
    )
