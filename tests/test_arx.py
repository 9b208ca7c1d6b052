"""ARX least squares from one QR of [Φ | y]: θ, its standard deviations, the residual and both
fits against the textbook formulas computed here by hand with numpy (lstsq, σ² (ΦᵀΦ)⁻¹, the
NRMSE of explicit residuals and simulations); the regressor is one array, built without copies."""

from __future__ import annotations

import numpy as np
import pytest

from cartctl.identification.arx import (
    IdentificationError,
    as_segments,
    augmented_regression,
    fit_arx,
    simulation_fit,
    stacked_regression,
)
from cartctl.model import ArxModel
from cartctl.signals import prbs, square

THETA = [-0.9356, 0.2173, 0.6466, -0.07751]


def _hand_regression(
    segments: list[tuple[np.ndarray, np.ndarray]], na: int, nb: int, nk: int, start: int
) -> tuple[np.ndarray, np.ndarray]:
    """Φ and y row by row from the defining equation, stacked over the experiments."""
    rows, targets = [], []
    for y, u in segments:
        for k in range(start, y.size):
            rows.append([-y[k - i] for i in range(1, na + 1)] + [u[k - nk - j] for j in range(nb)])
            targets.append(y[k])
    return np.array(rows), np.array(targets)


def _nrmse_fit(measured: np.ndarray, modelled: np.ndarray) -> float:
    return 100.0 * (
        1.0 - np.linalg.norm(measured - modelled) / np.linalg.norm(measured - measured.mean())
    )


def _noisy_experiments(seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    model = ArxModel.from_theta(THETA)
    u1 = square(10.0, cycles=3)
    u2 = prbs(8.0, duration_s=6.0, seed=seed)
    return [
        (model.simulate(u1) + rng.normal(0.0, 0.3, u1.size), u1),
        (np.array([1.0, 2.0]), np.array([0.5, -0.5])),  # too short: contributes no rows
        (model.simulate(u2) + rng.normal(0.0, 0.3, u2.size), u2),
    ]


@pytest.mark.parametrize(
    ("na", "nb", "nk", "start"),
    [(2, 2, 2, None), (3, 2, 1, None), (0, 4, 0, None), (1, 3, 3, 9)],
)
def test_fit_matches_the_textbook_formulas(na: int, nb: int, nk: int, start: int | None) -> None:
    segments = _noisy_experiments(seed=7)
    fit = fit_arx(segments, na=na, nb=nb, nk=nk, start=start)
    first = max(na, nk + nb - 1) if start is None else start
    phi, target = _hand_regression(segments, na, nb, nk, first)
    n, p = phi.shape

    reference = np.linalg.lstsq(phi, target, rcond=None)[0]
    np.testing.assert_allclose(
        fit.model.theta, reference, rtol=1e-12, atol=1e-12 * np.abs(reference).max()
    )
    residual = target - phi @ reference
    sigma2 = residual @ residual / (n - p)
    covariance = sigma2 * np.linalg.inv(phi.T @ phi)
    np.testing.assert_allclose(fit.theta_std, np.sqrt(np.diag(covariance)), rtol=1e-9)
    assert fit.residual_rms == pytest.approx(np.sqrt(np.mean(residual**2)), rel=1e-10)
    assert fit.fit_prediction_percent == pytest.approx(_nrmse_fit(target, phi @ reference), 1e-10)
    assert fit.n_samples == n

    measured = np.concatenate([y for y, _ in segments])
    simulated = np.concatenate([fit.model.simulate(u) for _, u in segments])
    assert fit.fit_simulation_percent == pytest.approx(_nrmse_fit(measured, simulated), 1e-10)


def test_simulation_fit_on_separate_evaluation_data() -> None:
    segments = _noisy_experiments(seed=3)
    clean = [(ArxModel.from_theta(THETA).simulate(u), u) for _, u in segments]
    fit = fit_arx(segments, eval_segments=clean)
    measured = np.concatenate([y for y, _ in clean])
    simulated = np.concatenate([fit.model.simulate(u) for _, u in clean])
    assert fit.fit_simulation_percent == pytest.approx(_nrmse_fit(measured, simulated), 1e-10)


def test_simulation_fit_of_a_diverging_model_and_of_a_constant_output() -> None:
    u = square(10.0, cycles=2)
    unstable = ArxModel.from_theta([-2.5, 1.2, 0.5, 0.1])  # a pole at 1.77: overflows
    assert simulation_fit(unstable, [(u, u)]) == -np.inf
    assert np.isnan(simulation_fit(ArxModel.from_theta(THETA), [(np.ones(u.size), u)]))


def test_the_regression_is_one_column_major_array_and_phi_y_are_its_views() -> None:
    segments = as_segments(_noisy_experiments(seed=1))
    phi_y = augmented_regression(segments, 2, 2, 2)
    phi, target = _hand_regression(segments, 2, 2, 2, 3)
    assert phi_y.flags.f_contiguous
    np.testing.assert_array_equal(phi_y, np.column_stack([phi, target]))
    phi_view, target_view = stacked_regression(segments, 2, 2, 2)
    np.testing.assert_array_equal(phi_view, phi)
    np.testing.assert_array_equal(target_view, target)
    assert phi_view.base is target_view.base is not None


def test_no_rows_and_rank_deficiency_are_refused() -> None:
    with pytest.raises(IdentificationError, match="too few samples"):
        fit_arx([(np.arange(3.0), np.array([0.0, 1.0, 0.0]))])
    u = square(10.0, cycles=2)
    with pytest.raises(IdentificationError, match="rank deficient"):
        fit_arx([(np.zeros(u.size), u)])  # the output's lags are zero columns
