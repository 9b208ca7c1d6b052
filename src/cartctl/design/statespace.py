"""A state-space realisation of an ARX motor model whose state has a documented meaning.

Pole placement and the Kalman estimator work on it and the runtime estimators carry its state,
so the state fed back is the state estimated (python-control's ``ss(tf)`` picks a state with no
useful meaning). It is the observer canonical form of G(z) = (β_1 z^{n−1} + … + β_n) / (z^n +
α_1 z^{n−1} + … + α_n) (n = ``model.order``, β the numerator padded to n)::

    x[k+1] = A x[k] + B u[k],   y[k] = C x[k],   A = [−α | I_{n−1}; 0],   B = β,   C = [1, 0, …, 0]

x_1[k] = y[k] is the modelled speed and x_j[k] (j ≥ 2) the part of y[k + j − 1] that inputs and
outputs up to k − 1 already fix, x_j[k] = Σ_{i=j..n} (β_i u[k+j−1−i] − α_i y[k+j−1−i]), all in
rad/s. For the report's (a z + b) / (z³ + c z² + d z): x_2[k] = y[k+1] + c y[k] (one step of
prediction) and x_3[k] = b u[k−1] (the delayed input). Always observable; minimal when numerator
and denominator share no root.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import InputError
from cartctl.model import ArxModel, check_extra_delay_ticks

__all__ = ["StateSpace", "realise", "uncontrollable_modes"]

_PBH_TOL = 1e-9
"""A PBH-test singular value below this fraction of the largest counts as rank loss."""


@dataclass(frozen=True, eq=False)
class StateSpace:
    """A discrete SISO system ``x[k+1] = A x + B u``, ``y = C x`` (A (n, n), B (n,) in rad/s per
    V, C (n,); filterpy's F and H) with sample period Ts (s)."""

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    period_s: float

    @property
    def order(self) -> int:
        """Number of states n."""
        return int(self.A.shape[0])

    def to_control(self):
        """The system as a python-control ``StateSpace`` with dt = Ts (B as a column, C as a row)."""
        import control

        n = self.order
        return control.ss(
            self.A, self.B.reshape(n, 1), self.C.reshape(1, n), [[0.0]], dt=self.period_s
        )

    def simulate(self, voltage_v: NDArray[np.float64]) -> NDArray[np.float64]:
        """Output y[k] (rad/s) for the input u[k] (V), shape (N,), from x[0] = 0 (scipy's dlsim)."""
        import scipy.signal

        u = np.asarray(voltage_v, dtype=float)
        if u.size == 0:
            return np.empty(0)
        n = self.order
        system = (
            self.A,
            self.B.reshape(n, 1),
            self.C.reshape(1, n),
            np.zeros((1, 1)),
            self.period_s,
        )
        _, y, _ = scipy.signal.dlsim(system, u)
        return np.asarray(y, dtype=float).ravel()

    def is_controllable(self) -> bool:
        """True when every mode can be moved by u (PBH test: rank [λI − A, B] = n for each λ)."""
        return not uncontrollable_modes(self.A, self.B)


def uncontrollable_modes(A: NDArray[np.float64], B: NDArray[np.float64]) -> list[complex]:
    """Eigenvalues of A (n, n) that u through B (n,) cannot move (PBH test); empty when (A, B)
    is controllable."""
    n = A.shape[0]
    bad: list[complex] = []
    scale = max(1.0, float(np.linalg.norm(A)), float(np.linalg.norm(B)))
    for lam in np.linalg.eigvals(A):
        pbh = np.hstack([lam * np.eye(n) - A, B.reshape(n, 1)])
        if np.linalg.svd(pbh, compute_uv=False)[-1] < _PBH_TOL * scale:
            bad.append(complex(lam))
    return bad


def realise(model: ArxModel, *, extra_delay_ticks: int = 0) -> StateSpace:
    """The observer canonical realisation of an ARX model (V → rad/s) with its input delay nk
    (≥ 1: u[k] is computed after y[k] is measured) plus ``extra_delay_ticks`` d ≥ 0, order
    max(na, nk + d + nb − 1) (``model.order + d`` for the report's structure); InputError for
    nk = 0 or a bad extra delay."""
    check_extra_delay_ticks(extra_delay_ticks, "extra_delay_ticks")
    if model.nk < 1:
        raise InputError(
            f"the model has no input delay (nk = {model.nk}); the controller needs nk >= 1 because "
            "it computes u[k] after measuring y[k]"
        )
    delayed = model.with_extra_delay(extra_delay_ticks)
    den = delayed.den()  # [1, α_1 … α_n]
    num = delayed.num()  # degree n − nk < n: strictly proper
    n = den.size - 1
    beta = np.zeros(n)
    beta[n - num.size :] = num
    A = np.zeros((n, n))
    A[:, 0] = 0.0 - den[1:]  # "0.0 −" keeps −0.0 out of the matrix
    A[: n - 1, 1:] = np.eye(n - 1)
    C = np.zeros(n)
    C[0] = 1.0
    return StateSpace(A, beta, C, model.period_s)
