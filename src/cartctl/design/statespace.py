"""A state-space realisation of an ARX motor model whose state has a documented meaning.

Where it sits: the first step of the ``design`` stage. Pole placement (:mod:`cartctl.design.poles`)
and the Kalman estimator (:mod:`cartctl.design.kalman`) both work on this realisation, and the
runtime estimators (:mod:`cartctl.runtime.kalman`) carry its state, so the state fed back is the
state estimated. python-control's ``ss(tf)`` would pick a state with no useful meaning.

The realisation is the *observer canonical form* of ``G(z) = (β_1 z^{n−1} + … + β_n) / (z^n + α_1
z^{n−1} + … + α_n)`` (n = ``model.order``, β = the numerator padded to n, α = the denominator after
its leading 1)::

    x[k+1] = A x[k] + B u[k],    y[k] = C x[k]

        ⎡ −α_1  1  0 … 0 ⎤        ⎡ β_1 ⎤
        ⎢ −α_2  0  1 … 0 ⎥        ⎢ β_2 ⎥
    A = ⎢   ⋮          ⋱ ⎥    B = ⎢  ⋮  ⎥    C = [1, 0, …, 0]
        ⎣ −α_n  0  0 … 0 ⎦        ⎣ β_n ⎦

The meaning of the state: x_1[k] = y[k] is the modelled speed (rad/s), and x_j[k] (j ≥ 2) is the
part of the speed y[k + j − 1] that the inputs and outputs up to tick k − 1 already fix::

    x_j[k] = Σ_{i=j..n} (β_i u[k + j − 1 − i] − α_i y[k + j − 1 − i])      (rad/s)

For the report's structure (a z + b) / (z³ + c z² + d z) (n = 3, delay included)::

    x_1[k] = y[k],   x_2[k] = a u[k−1] + b u[k−2] − d y[k−1],   x_3[k] = b u[k−1]

so x_2[k] = y[k+1] + c y[k]: one step of prediction, and x_3 holds the delayed input. Every state
is in rad/s. The realisation is minimal when numerator and denominator have no common root
(:meth:`StateSpace.is_controllable`); it is always observable.
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
    """A discrete single-input single-output system ``x[k+1] = A x + B u``, ``y = C x``.

    Attributes
    ----------
    A : ndarray, shape (n, n)
        State transition matrix (called F in filterpy).
    B : ndarray, shape (n,)
        Input vector (rad/s per V).
    C : ndarray, shape (n,)
        Output row (called H in filterpy); ``[1, 0, …, 0]`` in the observer form.
    period_s : float
        Sample period Ts (s).
    """

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
        import scipy.signal

        _, y, _ = scipy.signal.dlsim(system, u)
        return np.asarray(y, dtype=float).ravel()

    def is_controllable(self) -> bool:
        """True when every mode can be moved by u (PBH test: rank [λI − A, B] = n for each λ)."""
        return not uncontrollable_modes(self.A, self.B)

    def to_dict(self) -> dict[str, object]:
        """JSON form: ``{"A": [[...]], "B": [...], "C": [...], "period_s": Ts}``."""
        return {
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "period_s": self.period_s,
        }


def uncontrollable_modes(A: NDArray[np.float64], B: NDArray[np.float64]) -> list[complex]:
    """Eigenvalues of A that u cannot move (PBH test), for messages and checks.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n,)

    Returns
    -------
    list of complex
        Empty when (A, B) is controllable.
    """
    n = A.shape[0]
    bad: list[complex] = []
    scale = max(1.0, float(np.linalg.norm(A)), float(np.linalg.norm(B)))
    for lam in np.linalg.eigvals(A):
        pbh = np.hstack([lam * np.eye(n) - A, B.reshape(n, 1)])
        if np.linalg.svd(pbh, compute_uv=False)[-1] < _PBH_TOL * scale:
            bad.append(complex(lam))
    return bad


def realise(model: ArxModel, *, extra_delay_ticks: int = 0) -> StateSpace:
    """The observer canonical realisation of an ARX model (see the module docstring).

    Parameters
    ----------
    model : ArxModel
        The motor model, voltage (V) to speed (rad/s). Its input delay nk must be ≥ 1: the
        runtime computes u[k] after measuring y[k], so the model may not feed u[k] through to y[k].
    extra_delay_ticks : int
        Extra whole ticks of input delay, d ≥ 0 (a PC-side serial loop). The model is realised as
        if its delay were nk + d: d more states for the report's structure (fewer when the
        numerator has roots at z = 0 to absorb the delay); x_1 is still the speed.

    Returns
    -------
    StateSpace
        Order max(na, nk + d + nb − 1): ``model.order + extra_delay_ticks`` for the report's
        structure.

    Raises
    ------
    InputError
        nk = 0, or a negative or fractional extra delay.
    """
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
