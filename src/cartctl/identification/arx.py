"""ARX least squares, the report's estimator (equation 6, table 1), for general orders::

    y[k] = φ(k)ᵀ θ + e[k],   φ(k) = [−y[k−1] … −y[k−na], u[k−nk] … u[k−nk−nb+1]]

(y in rad/s, u in V), from one Householder QR of [Φ | y] over all experiments (no regressor
crosses their boundaries), which also gives the residual norm and θ's covariance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import qr, solve_triangular

from cartctl.cart import PERIOD_S
from cartctl.choices import is_whole
from cartctl.errors import InputError
from cartctl.measures.metrics import finite_or_none, fit_from_norms, fit_percent, sum_squares
from cartctl.model import ArxModel

Segment = tuple[ArrayLike, ArrayLike]
"""One experiment: (output y in rad/s, input u in V), equally long 1-D arrays."""

Checked = tuple[NDArray[np.float64], NDArray[np.float64]]
"""One experiment as float arrays, from :func:`as_segments`."""

RCOND = 1e-10
"""Smallest singular value of Φ, relative to its largest, before Φ counts as rank deficient."""

MIN_ROWS_PER_PARAMETER = 10
"""Fewer equations per parameter than this gives no meaningful model, and is refused."""


class IdentificationError(InputError):
    """The data cannot give a meaningful model (no excitation, too short, rank deficient)."""


@dataclass(frozen=True)
class ArxFit:
    """An identified model, θ's covariance Σ (:func:`theta_covariance`, on the data the fit is
    on), NRMSE fits (%) of the simulation from rest and of the one-step prediction, and the RMS
    (rad/s) of the equation (ARX) or simulation (OE) error over ``n_samples`` equations."""

    model: ArxModel
    theta_cov: NDArray[np.float64]
    fit_simulation_percent: float
    fit_prediction_percent: float
    residual_rms: float
    n_samples: int
    method: str = "arx"

    @property
    def theta_std(self) -> NDArray[np.float64]:
        """σ of each θ entry: √diag Σ."""
        return np.sqrt(np.diag(self.theta_cov))

    def on(self, segments: Sequence[Segment]) -> Self:
        """This fit with its simulation and prediction fits on other data (validation)."""
        return replace(
            self,
            fit_simulation_percent=simulation_fit(self.model, segments),
            fit_prediction_percent=prediction_fit(self.model, segments),
        )

    def theta_names(self) -> list[str]:
        """Names of the θ entries: the report's c, d, a, b for its structure; a1…, b0… otherwise."""
        m = self.model
        if m.na == 2 and m.nb == 2:
            return ["c", "d", "a", "b"]
        return [f"a{i + 1}" for i in range(m.na)] + [f"b{j}" for j in range(m.nb)]

    def to_dict(self) -> dict[str, Any]:
        """``identify --json`` entry of one motor (plus na, nb, method, residual_rms, n_samples)."""
        m = self.model
        out: dict[str, Any] = {"theta": m.theta.tolist(), "nk": m.nk, "na": m.na, "nb": m.nb}
        out |= {"num": m.num().tolist(), "den": m.den().tolist()}
        out |= {"theta_std": self.theta_std.tolist()}
        fits = ("fit_simulation_percent", "fit_prediction_percent")
        out |= {k: finite_or_none(getattr(self, k)) for k in fits}
        out |= {"method": self.method, "residual_rms": finite_or_none(self.residual_rms)}
        return out | {"n_samples": self.n_samples}


def as_segments(segments: Sequence[Segment]) -> list[Checked]:
    """Experiments as float arrays; a clear error for bad shapes or values."""
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


def rows_from(segments: Sequence[Checked], start: int) -> list[Checked]:
    """The experiments longer than ``start`` samples; refuses none."""
    used = [(y, u) for y, u in segments if y.size > start]
    if not used:
        raise IdentificationError(
            f"too few samples: the model needs more than {start} samples per experiment"
        )
    return used


def augmented_regression(
    segments: Sequence[Checked], na: int, nb: int, nk: int, start: int | None = None
) -> NDArray[np.float64]:
    """[Φ | y] of all experiments in one Fortran-order array, ready for an in-place QR: rows
    k = ``start`` (default :func:`first_row`) … n − 1 of each experiment longer than ``start``."""
    start = first_row(na, nb, nk) if start is None else start
    used = rows_from(segments, start)
    rows = sum(y.size - start for y, _ in used)
    out = np.empty((rows, na + nb + 1), order="F")
    row = 0
    for y, u in used:
        n = y.size
        block = out[row : row + n - start]
        for i in range(1, na + 1):  # filled from shifted views, without intermediate arrays
            np.negative(y[start - i : n - i], out=block[:, i - 1])
        for j in range(nb):
            block[:, na + j] = u[start - nk - j : n - nk - j]
        block[:, na + nb] = y[start:]
        row += n - start
    return out


def stacked_regression(
    segments: Sequence[Checked], na: int, nb: int, nk: int, start: int | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Φ and target as views of :func:`augmented_regression`'s array."""
    phi_y = augmented_regression(segments, na, nb, nk, start)
    return phi_y[:, :-1], phi_y[:, -1]


def check_orders(na: int, nb: int, nk: int) -> None:
    """Refuse nonsense orders with a message naming the parameter (and its option)."""
    for name, value, low in (("na (--na)", na, 0), ("nb (--nb)", nb, 1), ("nk (--delay)", nk, 0)):
        if not is_whole(value) or value < low or value > 50:
            raise InputError(f"{name} must be a whole number in {low}..50, got {value!r}")


def theta_covariance(r: ArrayLike, residual_ss: float, rows: int) -> NDArray[np.float64]:
    """Σ = σ̂² (JᵀJ)⁻¹ = σ̂² R⁻¹ R⁻ᵀ of a least-squares θ̂ (J = Φ for ARX, the simulation's
    Jacobian for OE), from the triangular R of J = QR and the residual sum of squares over
    ``rows`` equations, σ̂² = Σ e² / (rows − d); NaN throughout when R is singular."""
    r = np.asarray(r, dtype=float)
    d = r.shape[1]
    if r.shape[0] < d:  # fewer equations than parameters: a wide R, singular
        return np.full((d, d), np.nan)
    try:
        r_inv = solve_triangular(r, np.eye(d), check_finite=False)
    except np.linalg.LinAlgError:
        return np.full((d, d), np.nan)
    return residual_ss / max(rows - d, 1) * (r_inv @ r_inv.T)


def least_squares(
    phi_y: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """θ, ‖y − Φθ‖ and θ's covariance from one QR of [Φ | y] (destroyed): with
    [Φ | y] = Q [[R, z], [0, ρ]], θ = R⁻¹ z, ‖y − Φθ‖ = |ρ|, Σ of :func:`theta_covariance`.
    Refuses fewer than :data:`MIN_ROWS_PER_PARAMETER` rows per parameter and a rank-deficient Φ.
    """
    n, p = phi_y.shape[0], phi_y.shape[1] - 1
    if n < MIN_ROWS_PER_PARAMETER * p:
        raise IdentificationError(
            f"too few samples for this model: {n} equations for {p} parameters; "
            f"record at least {MIN_ROWS_PER_PARAMETER * p} samples beyond the first few"
        )
    # mode="raw" returns the triangular factor without forming Q (mode="r" would copy all rows)
    _, r_aug = qr(phi_y, mode="raw", overwrite_a=True, check_finite=False)
    r, z, rho = r_aug[:p, :p], r_aug[:p, p], float(abs(r_aug[p, p]))
    sv = np.linalg.svd(r, compute_uv=False)
    if sv[0] == 0.0 or sv[-1] <= RCOND * sv[0]:
        cond = np.inf if sv[-1] == 0.0 else sv[0] / sv[-1]
        raise IdentificationError(
            f"the regression is rank deficient (condition number {cond:.3g}): the data does not "
            "excite this model; use a richer excitation (square, prbs, multisine) or lower orders"
        )
    theta = solve_triangular(r, z, check_finite=False)
    return theta, rho, theta_covariance(r, rho**2, n)


def simulation_fit(model: ArxModel, segments: Sequence[Segment]) -> float:
    """NRMSE fit (%) of ``model`` simulated from rest on each experiment, over all of them
    together (without concatenating them); NaN for a constant output, and −inf, worse than any
    model, for an unstable model (a pole on or outside the unit circle) or a simulation that
    overflows: an unstable model runs away, within the data or after it, so it has no fit."""
    data = as_segments(segments)
    if not model.is_stable():
        return float("-inf")
    with np.errstate(over="ignore", invalid="ignore"):  # a marginal model may still overflow
        sims = [model.simulate(u) for _, u in data]
        if not all(np.isfinite(sim).all() for sim in sims):
            return float("-inf")
        count = sum(y.size for y, _ in data)
        mean = sum(float(y.sum()) for y, _ in data) / count if count else float("nan")
        error2 = spread2 = 0.0
        for (y, _), work in zip(data, sims, strict=True):  # each simulation is reused as work space
            np.subtract(y, work, out=work)
            error2 += sum_squares(work)
            np.subtract(y, mean, out=work)
            spread2 += sum_squares(work)
        return fit_from_norms(np.sqrt(error2), np.sqrt(spread2))


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
    period_s: float = PERIOD_S,
    start: int | None = None,
    eval_segments: Sequence[Segment] | None = None,
) -> ArxFit:
    """Fit an ARX model by least squares to (speed rad/s, voltage V) experiments, from regression
    row ``start`` (default: the first with all regressors inside). The simulation fit is on
    ``eval_segments`` when given: the raw data, so fits with and without a prefilter compare."""
    check_orders(na, nb, nk)
    data = as_segments(segments)
    inputs = [u for _, u in data if u.size]
    if inputs and min(float(u.min()) for u in inputs) == max(float(u.max()) for u in inputs):
        raise IdentificationError(
            f"the input voltage is constant ({inputs[0][0]:g} V) throughout: it does not excite "
            "the motor; record an excitation experiment (cartctl excite --signal square)"
        )
    phi_y = augmented_regression(data, na, nb, nk, start)
    rows = phi_y.shape[0]
    target = phi_y[:, -1]
    spread = float(np.sqrt(sum_squares(target - target.mean())))  # before the QR overwrites phi_y
    theta, residual_norm, theta_cov = least_squares(phi_y)
    model = ArxModel.from_theta(theta, na=na, nb=nb, nk=nk, period_s=period_s)
    simulated = simulation_fit(model, eval_segments or data)
    predicted = fit_from_norms(residual_norm, spread)
    rms = float(residual_norm / np.sqrt(rows))
    return ArxFit(model, theta_cov, simulated, predicted, rms, int(rows))
