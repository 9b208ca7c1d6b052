"""Output-error refinement: minimise the simulation error over θ, starting from the ARX estimate.

ARX minimises the equation error, which under measurement noise biases θ (the report's dilemma:
unfiltered too fast, filtered too slow). The output-error criterion

    V(θ) = Σ_k (y[k] − ŷ(k, θ))²,     ŷ = B(q) q⁻ⁿᵏ / A(q) u    (simulated from rest)

is unbiased for white measurement noise. It is solved with scipy.optimize.least_squares using the
exact Jacobian, itself obtained by filtering:

    ∂ŷ/∂a_i = −q⁻ⁱ ŷ / A(q),      ∂ŷ/∂b_j = q⁻⁽ⁿᵏ⁺ʲ⁾ u / A(q).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, signal

from cartctl.errors import InputError
from cartctl.identification.arx import (
    ArxFit,
    IdentificationError,
    Segment,
    as_segments,
    prediction_fit,
    simulation_fit,
)
from cartctl.model import ArxModel


def _shift(x: NDArray[np.float64], lag: int) -> NDArray[np.float64]:
    out = np.zeros_like(x)
    out[lag:] = x[: x.size - lag]
    return out


def _simulate_with_jacobian(
    theta: NDArray[np.float64], u: NDArray[np.float64], na: int, nb: int, nk: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a = np.concatenate([[1.0], theta[:na]])
    b = np.concatenate([np.zeros(nk), theta[na:]])
    y_hat = signal.lfilter(b, a, u)
    w = signal.lfilter([1.0], a, y_hat)
    v = signal.lfilter([1.0], a, u)
    jac = np.empty((u.size, na + nb))
    for i in range(na):
        jac[:, i] = -_shift(w, i + 1)
    for j in range(nb):
        jac[:, na + j] = _shift(v, nk + j)
    return y_hat, jac


def fit_oe(
    segments: Sequence[Segment],
    initial: ArxModel,
    *,
    max_evaluations: int = 200,
    eval_segments: Sequence[Segment] | None = None,
) -> ArxFit:
    """Refine a model by output-error least squares (simulation error), from ``initial``.

    Parameters
    ----------
    segments : sequence of (y, u)
        Experiments (rad/s, V), each simulated from rest.
    initial : ArxModel
        Starting point, usually the ARX estimate; its orders and delay are kept.
    max_evaluations : int
        Limit on function evaluations.
    eval_segments : sequence of (y, u), optional
        Data for the reported simulation fit (default ``segments``).

    Returns
    -------
    ArxFit
        ``method='oe'``; ``theta_std`` from the Jacobian at the optimum, σ̂ √diag((JᵀJ)⁻¹).
    """
    if not initial.is_stable():
        raise IdentificationError(
            "the ARX starting point is unstable, so the output-error simulation diverges; "
            "check the data or the orders"
        )
    data = as_segments(segments)
    na, nb, nk = initial.na, initial.nb, initial.nk
    y_all = np.concatenate([y for y, _ in data])

    def unstable(theta: NDArray[np.float64]) -> bool:
        return na > 0 and bool(np.max(np.abs(np.roots(np.concatenate([[1.0], theta[:na]])))) >= 1.0)

    def residual(theta: NDArray[np.float64]) -> NDArray[np.float64]:
        if unstable(theta):  # a large finite cost: the trust region rejects the step and shrinks
            return np.full_like(y_all, 1e6)
        return y_all - np.concatenate(
            [_simulate_with_jacobian(theta, u, na, nb, nk)[0] for _, u in data]
        )

    def jacobian(theta: NDArray[np.float64]) -> NDArray[np.float64]:
        if unstable(theta):
            return np.zeros((y_all.size, na + nb))
        return -np.concatenate([_simulate_with_jacobian(theta, u, na, nb, nk)[1] for _, u in data])

    if max_evaluations < 1:
        raise InputError(f"max_evaluations must be at least 1, got {max_evaluations}")
    result = optimize.least_squares(
        residual, initial.theta, jac=jacobian, method="trf", x_scale="jac", max_nfev=max_evaluations
    )
    theta = result.x
    model = ArxModel.from_theta(theta, na=na, nb=nb, nk=nk, period_s=initial.period_s)
    err = result.fun
    n, p = result.jac.shape
    sigma2 = float(err @ err) / max(n - p, 1)
    try:
        cov = sigma2 * np.linalg.inv(result.jac.T @ result.jac)
        theta_std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        theta_std = np.full(p, np.nan)
    return ArxFit(
        model=model,
        theta_std=theta_std,
        fit_simulation_percent=simulation_fit(model, eval_segments or data),
        fit_prediction_percent=prediction_fit(model, data),
        residual_rms=float(np.sqrt(np.mean(err**2))),
        n_samples=int(n),
        method="oe",
    )
