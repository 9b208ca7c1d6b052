"""ARX least squares: the report's estimator, with parameter uncertainty and labelled fits.

The regression of the report (equation 6, table 1), for general orders::

    y[k] = φ(k)ᵀ θ + e[k],   φ(k) = [−y[k−1] … −y[k−na], u[k−nk] … u[k−nk−nb+1]]

θ is the least-squares solution, computed from a QR factorisation of the regressor matrix (not the
normal equations). Several experiments (segments) are stacked without regressors across their
boundaries. Pure numpy/scipy: arrays in, frozen results out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import solve_triangular

from cartctl.errors import InputError
from cartctl.metrics import finite_or_none, fit_percent
from cartctl.model import ArxModel

Segment = tuple[ArrayLike, ArrayLike]
"""One experiment: (output y in rad/s, input u in V), equally long 1-D arrays."""

RCOND = 1e-10
"""Smallest singular value of the regressor matrix, relative to its largest, before it counts as rank deficient."""


MIN_ROWS_PER_PARAMETER = 10
"""Fewer equations per parameter than this gives no meaningful model, and is refused."""


class IdentificationError(InputError):
    """The data cannot give a meaningful model (no excitation, too short, rank deficient)."""


@dataclass(frozen=True)
class ArxFit:
    """An identified model with its uncertainty and fit figures.

    Attributes
    ----------
    model : ArxModel
    theta_std : ndarray, shape (na + nb,)
        Standard deviation of each θ entry, σ̂ √diag((ΦᵀΦ)⁻¹) for ARX (the Jacobian's for OE).
    fit_simulation_percent : float
        NRMSE fit (%) of the model simulated from rest on the input alone.
    fit_prediction_percent : float
        NRMSE fit (%) of the one-step-ahead prediction from past measurements.
    residual_rms : float
        RMS of the equation (ARX) or simulation (OE) error (rad/s).
    n_samples : int
        Number of equations (regression rows) used.
    method : str
        'arx' or 'oe'.
    """

    model: ArxModel
    theta_std: NDArray[np.float64]
    fit_simulation_percent: float
    fit_prediction_percent: float
    residual_rms: float
    n_samples: int
    method: str = "arx"

    def theta_names(self) -> list[str]:
        """Names of the θ entries: the report's c, d, a, b for its structure; a1…, b0… otherwise."""
        m = self.model
        if m.na == 2 and m.nb == 2:
            return ["c", "d", "a", "b"]
        return [f"a{i + 1}" for i in range(m.na)] + [f"b{j}" for j in range(m.nb)]

    def to_dict(self) -> dict[str, Any]:
        """Contract-3 entry of one motor (plus na, nb, method, residual_rms, n_samples)."""
        m = self.model
        return {
            "theta": m.theta.tolist(),
            "nk": m.nk,
            "na": m.na,
            "nb": m.nb,
            "num": m.num().tolist(),
            "den": m.den().tolist(),
            "theta_std": self.theta_std.tolist(),
            "fit_simulation_percent": finite_or_none(self.fit_simulation_percent),
            "fit_prediction_percent": finite_or_none(self.fit_prediction_percent),
            "method": self.method,
            "residual_rms": finite_or_none(self.residual_rms),
            "n_samples": self.n_samples,
        }


def as_segments(
    segments: Sequence[Segment],
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Check and convert experiments to float arrays; a clear error for bad shapes or values."""
    out = []
    if not segments:
        raise IdentificationError("no data to identify from")
    for i, (y, u) in enumerate(segments):
        y_arr, u_arr = np.asarray(y, dtype=float), np.asarray(u, dtype=float)
        if y_arr.ndim != 1 or u_arr.shape != y_arr.shape:
            raise InputError(
                f"experiment {i + 1}: output and input must be 1-D and equally long, "
                f"got shapes {y_arr.shape} and {u_arr.shape}"
            )
        if not (np.isfinite(y_arr).all() and np.isfinite(u_arr).all()):
            raise IdentificationError(f"experiment {i + 1} holds NaN or infinite values")
        out.append((y_arr, u_arr))
    return out


def first_row(na: int, nb: int, nk: int) -> int:
    """The first sample k whose regressors are all inside the data: max(na, nk + nb − 1)."""
    return max(na, nk + nb - 1)


def regression(
    y: NDArray[np.float64],
    u: NDArray[np.float64],
    na: int,
    nb: int,
    nk: int,
    start: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Regressor matrix Φ, shape (n − start, na + nb), and target y[start:], for one experiment.

    ``start`` is at least :func:`first_row` (:func:`stacked_regression` chooses it).
    """
    n = y.size
    cols = [-y[start - i : n - i] for i in range(1, na + 1)]
    cols += [u[start - nk - j : n - nk - j] for j in range(nb)]
    return np.column_stack(cols) if cols else np.empty((n - start, 0)), y[start:]


def stacked_regression(
    segments: Sequence[tuple[NDArray[np.float64], NDArray[np.float64]]],
    na: int,
    nb: int,
    nk: int,
    start: int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Φ and target of several experiments, stacked (no regressor crosses a boundary)."""
    start = first_row(na, nb, nk) if start is None else start
    parts = [regression(y, u, na, nb, nk, start) for y, u in segments if y.size > start]
    if not parts:
        raise IdentificationError(
            f"too few samples: the model needs more than {start} samples per experiment"
        )
    phi = np.concatenate([p[0] for p in parts]) if len(parts) > 1 else parts[0][0]
    target = np.concatenate([p[1] for p in parts]) if len(parts) > 1 else parts[0][1]
    return phi, target


def check_orders(na: int, nb: int, nk: int) -> None:
    """Refuse nonsense orders with a message naming the parameter."""
    for name, value, low in (("na", na, 0), ("nb", nb, 1), ("nk", nk, 0)):
        if not isinstance(value, int | np.integer) or value < low or value > 50:
            raise InputError(f"{name} must be a whole number in {low}..50, got {value!r}")


def least_squares(
    phi: NDArray[np.float64], target: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Solve min ‖Φθ − y‖ by QR; return θ, the residuals and the θ standard deviations.

    Raises
    ------
    IdentificationError
        Fewer equations than parameters + 1, or a rank-deficient Φ (the data does not excite
        the model).
    """
    n, p = phi.shape
    if n < MIN_ROWS_PER_PARAMETER * p:
        raise IdentificationError(
            f"too few samples for this model: {n} equations for {p} parameters; "
            f"record at least {MIN_ROWS_PER_PARAMETER * p} samples beyond the first few"
        )
    q, r = np.linalg.qr(phi, mode="reduced")
    sv = np.linalg.svd(r, compute_uv=False)
    if sv[0] == 0.0 or sv[-1] <= RCOND * sv[0]:
        cond = np.inf if sv[-1] == 0.0 else sv[0] / sv[-1]
        raise IdentificationError(
            f"the regression is rank deficient (condition number {cond:.3g}): the data does not "
            "excite this model; use a richer excitation (square, prbs, multisine) or lower orders"
        )
    theta = solve_triangular(r, q.T @ target)
    residual = target - phi @ theta
    sigma2 = float(residual @ residual) / (n - p)
    r_inv = solve_triangular(r, np.eye(p))
    theta_std = np.sqrt(sigma2 * np.sum(r_inv**2, axis=1))
    return theta, residual, theta_std


def simulation_fit(model: ArxModel, segments: Sequence[Segment]) -> float:
    """NRMSE fit (%) of the model simulated from rest on each experiment's input, all samples."""
    ys, sims = [], []
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable model may diverge
        for y, u in as_segments(segments):
            ys.append(y)
            sims.append(model.simulate(u))
        sim = np.concatenate(sims)
        if not np.isfinite(sim).all():
            return float("-inf")
        return fit_percent(np.concatenate(ys), sim)


def prediction_fit(model: ArxModel, segments: Sequence[Segment]) -> float:
    """NRMSE fit (%) of the one-step-ahead prediction φ(k)ᵀθ on the experiments."""
    phi, target = stacked_regression(as_segments(segments), model.na, model.nb, model.nk)
    return fit_percent(target, phi @ model.theta)


def fit_arx(
    segments: Sequence[Segment],
    *,
    na: int = 2,
    nb: int = 2,
    nk: int = 2,
    period_s: float = 0.01,
    start: int | None = None,
    eval_segments: Sequence[Segment] | None = None,
) -> ArxFit:
    """Fit an ARX model by least squares (the report's method).

    Parameters
    ----------
    segments : sequence of (y, u)
        Experiments: measured speed (rad/s) and commanded voltage (V) per tick, possibly
        prefiltered.
    na, nb, nk : int
        Orders and input delay (2, 2, 2 is the report's structure).
    period_s : float
        Sample period (s).
    start : int, optional
        First regression row (defaults to the first with all regressors inside the data).
    eval_segments : sequence of (y, u), optional
        Data for the simulation fit (default: ``segments``). Pass the raw data when
        ``segments`` is prefiltered, so fits with and without a filter compare on equal terms.

    Returns
    -------
    ArxFit
    """
    check_orders(na, nb, nk)
    data = as_segments(segments)
    u_all = np.concatenate([u for _, u in data])
    if np.ptp(u_all) == 0.0:
        raise IdentificationError(
            f"the input voltage is constant ({u_all[0]:g} V) throughout: it does not excite the "
            "motor; record an excitation experiment (cartctl excite --signal square)"
        )
    phi, target = stacked_regression(data, na, nb, nk, start)
    theta, residual, theta_std = least_squares(phi, target)
    model = ArxModel.from_theta(theta, na=na, nb=nb, nk=nk, period_s=period_s)
    return ArxFit(
        model=model,
        theta_std=theta_std,
        fit_simulation_percent=simulation_fit(model, eval_segments or data),
        fit_prediction_percent=fit_percent(target, phi @ theta),
        residual_rms=float(np.sqrt(np.mean(residual**2))),
        n_samples=int(target.size),
        method="arx",
    )
