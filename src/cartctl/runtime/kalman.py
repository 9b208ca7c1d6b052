"""Kalman speed estimators for the 10 ms loop: the fixed-gain one, and one for timing noise.

Where it sits: the runtime, stepped once per tick by a controller
(:class:`~cartctl.runtime.statefeedback.StateFeedbackController`) or by the loop, in the order of
:mod:`cartctl.runtime.base`: ``correct(y[k])`` then ``predict(u[k])``. Both run a
:class:`~cartctl.design.kalman.KalmanDesign` (state x = [x_1 … x_n, b]; x_1 is the speed, rad/s)::

    correct:  x̂[k|k]   = x̂[k|k−1] + L (y[k] − C x̂[k|k−1])
    predict:  x̂[k+1|k] = A x̂[k|k] + B u[k]

:class:`SteadyStateSpeedEstimator` uses the fixed steady-state L with plain floats (a design's P
is stationary, so a propagated covariance would keep that gain); :class:`KalmanSpeedEstimator`
propagates the covariance, for a design with timing noise, whose process noise moves with each
change of the command. ``correct`` returns x̂_1[k|k] (the design's C is [1, 0, …]), the
estimate of the *measured* speed, an average over the last tick; after ``predict``, ``state[0]``
is x̂_1[k+1|k], and the mean of the two estimates the true speed at tick k (see
:mod:`cartctl.design.kalman`), which the state-feedback controller reports.
A non-finite measurement is skipped (the prediction stands) and a non-finite voltage counts as
0 V (what the cart applies), so a glitch never poisons the state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from cartctl.runtime.base import SpeedEstimator
from cartctl.runtime.elementwise import Value


@dataclass(frozen=True, eq=False)
class KalmanDesign:
    """A steady-state Kalman filter for the speed (names as in the literature).

    The state is x = [x_1 … x_n, b]: the n states of the realisation (rad/s; x_1 is the speed),
    then, when ``has_bias``, the input disturbance b (V). m = n + 1 with the bias, else n.

    Attributes
    ----------
    A : ndarray, shape (m, m)
        State transition (F in filterpy).
    B : ndarray, shape (m,)
        Input vector (rad/s per V); 0 in the bias row.
    C : ndarray, shape (m,)
        Measurement row (H in filterpy), [1, 0, …, 0].
    Q : ndarray, shape (m, m)
        Process-noise covariance per tick: σ_w² B_x B_xᵀ on the realisation, σ_b² on the bias.
    R : float
        Measurement-noise variance ((rad/s)²).
    P : ndarray, shape (m, m)
        Steady-state a priori covariance (the DARE solution), P[k|k−1].
    L : ndarray, shape (m,)
        Steady-state filter gain, P Cᵀ (C P Cᵀ + R)⁻¹.
    n_model_states : int
        n, the realisation's order (the states a state-feedback gain acts on).
    period_s : float
        Ts (s).
    process_noise_std_v, bias_drift_std_v, measurement_noise_std_rad_s : float
        The noise levels the design used (σ_w in V, σ_b in V per tick, √R in rad/s: the total,
        the encoder's quantisation and ``design --measurement-noise`` together).
    timing_noise_std_ticks : float
        σ_ε, the uncertainty of when a command lands (ticks); 0 (the default, and what a file
        without it gets): Q is fixed. Above 0 the estimator adds, at each prediction, the
        process noise of a command change Δu[k] = u[k] − u[k−1] landing ε ticks early or late, which
        acts as an extra input −ε Δu: Q[k] = Q + (σ_ε Δu[k])² B Bᵀ (:class:`KalmanSpeedEstimator`).
        P and L stay those of Q (between command changes the gain returns to L).
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    Q: NDArray[np.float64]
    R: float
    P: NDArray[np.float64]
    L: NDArray[np.float64]
    n_model_states: int
    period_s: float
    process_noise_std_v: float
    bias_drift_std_v: float
    measurement_noise_std_rad_s: float
    timing_noise_std_ticks: float = 0.0

    def timing_covariance(self, change_v: float) -> NDArray[np.float64]:
        """Q[k] = Q + (σ_ε Δu)² B Bᵀ, the process noise of a prediction after a command change of
        ``change_v`` (V); Q itself when σ_ε = 0."""
        extra = (self.timing_noise_std_ticks * change_v) ** 2
        return self.Q + extra * np.outer(self.B, self.B) if extra > 0.0 else np.array(self.Q)

    @property
    def has_bias(self) -> bool:
        """True when the state ends with the input-disturbance state b."""
        return self.A.shape[0] > self.n_model_states

    def posterior_covariance(self) -> NDArray[np.float64]:
        """Steady-state a posteriori covariance P[k|k] = (I − L C) P, shape (m, m)."""
        m = self.A.shape[0]
        return (np.eye(m) - np.outer(self.L, self.C)) @ self.P

    def poles(self) -> NDArray[np.complex128]:
        """Estimator poles: eigenvalues of (I − L C) A, shape (m,), sorted by magnitude."""
        m = self.A.shape[0]
        eig = np.linalg.eigvals((np.eye(m) - np.outer(self.L, self.C)) @ self.A)
        return np.array(sorted(eig.astype(complex), key=lambda p: (abs(p), p.imag)))

    def to_dict(self) -> dict[str, object]:
        """JSON form: the matrices as nested lists, the noise levels and ``estimator_poles``."""
        return {
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "Q": self.Q.tolist(),
            "R": self.R,
            "P": self.P.tolist(),
            "L": self.L.tolist(),
            "n_model_states": self.n_model_states,
            "has_bias": self.has_bias,
            "period_s": self.period_s,
            "process_noise_std_v": self.process_noise_std_v,
            "bias_drift_std_v": self.bias_drift_std_v,
            "measurement_noise_std_rad_s": self.measurement_noise_std_rad_s,
            "timing_noise_std_ticks": self.timing_noise_std_ticks,
            "estimator_poles": [[float(p.real), float(p.imag)] for p in self.poles()],
        }


__all__ = [
    "FilterTerms",
    "KalmanSpeedEstimator",
    "StateEstimator",
    "SteadyStateSpeedEstimator",
    "filter_correct",
    "filter_predict",
]


@runtime_checkable
class StateEstimator(SpeedEstimator, Protocol):
    """A speed estimator that also exposes its whole state, for state feedback."""

    @property
    def state(self) -> NDArray[np.float64]:
        """The current state estimate x̂, shape (m,): after ``correct``, x̂[k|k]."""
        ...


class KalmanSpeedEstimator:
    """The Kalman filter with its covariance propagated, for a design with timing noise.

    Parameters
    ----------
    design : KalmanDesign
        A, B, C, Q, R and the starting covariance P[0|−1] = P come from here; x̂ starts at 0.

    Each ``predict(u[k])`` propagates the covariance with Q[k] = Q + (σ_ε (u[k] − u[k−1]))² B Bᵀ
    (u[−1] = 0 after a reset; σ_ε is the design's ``timing_noise_std_ticks``): the command just
    sent may land a fraction of a tick earlier or later than the model says, so the prediction
    after a jump is trusted less and the next measurement counts more. ``correct`` uses the gain
    L[k] = P Cᵀ / (C P Cᵀ + R) and the Joseph form of the covariance update. With σ_ε = 0 the
    gain stays L, and :class:`SteadyStateSpeedEstimator` computes the same, faster.
    """

    def __init__(self, design: KalmanDesign) -> None:
        self.design = design
        self._eye = np.eye(design.A.shape[0])
        self.reset()

    def reset(self) -> None:
        """State at rest (x̂ = 0), covariance back to the design's P."""
        self._x = np.zeros(self.design.A.shape[0])
        self._P = np.array(self.design.P, dtype=float)
        self._gain = np.array(self.design.L, dtype=float)
        self._last_voltage_v = 0.0

    def correct(self, measured_rad_s: float) -> float:
        """Update with the speed measured at this tick (rad/s); return x̂_1[k|k] (rad/s)."""
        if math.isfinite(measured_rad_s):
            d, P = self.design, self._P
            PC = P @ d.C
            gain = PC / float(d.C @ PC + d.R)
            self._x = self._x + gain * (float(measured_rad_s) - float(d.C @ self._x))
            joseph = self._eye - np.outer(gain, d.C)
            self._P = joseph @ P @ joseph.T + d.R * np.outer(gain, gain)
            self._gain = gain
        return float(self._x[0])

    def predict(self, voltage_v: float) -> None:
        """Propagate state and covariance with the voltage applied at this tick (V)."""
        d = self.design
        u = float(voltage_v) if math.isfinite(voltage_v) else 0.0
        Q = d.timing_covariance(u - self._last_voltage_v)
        self._last_voltage_v = u
        self._x = d.A @ self._x + d.B * u
        self._P = d.A @ self._P @ d.A.T + Q

    @property
    def state(self) -> NDArray[np.float64]:
        """x̂, shape (m,) (a copy)."""
        return self._x.copy()

    def state_values(self) -> list[float]:
        """x̂ as a list of floats (a copy), for the per-tick arithmetic of state feedback."""
        return self._x.tolist()

    @property
    def gain(self) -> NDArray[np.float64]:
        """The latest gain L[k], shape (m,)."""
        return self._gain.copy()


class FilterTerms(NamedTuple):
    """A :class:`KalmanDesign`'s fixed-gain filter as plain floats, its zeros left out.

    Attributes
    ----------
    L : tuple of float
        The gain, one entry per state.
    C : tuple of (int, float)
        The measurement row's non-zero entries (state index, value).
    AB : tuple of (tuple of (int, float), float)
        Per state: the non-zero entries of its row of A (column, value), and its entry of B.
    """

    L: tuple[float, ...]
    C: tuple[tuple[int, float], ...]
    AB: tuple[tuple[tuple[tuple[int, float], ...], float], ...]

    @classmethod
    def from_design(cls, design: KalmanDesign) -> FilterTerms:
        """The terms of ``design`` (the observer form has at most three entries per row of A)."""
        m = design.A.shape[0]
        rows = tuple(tuple((j, float(a)) for j, a in enumerate(design.A[i]) if a != 0.0)
                     for i in range(m))  # fmt: skip
        return cls(tuple(float(v) for v in design.L),
                   tuple((j, float(c)) for j, c in enumerate(design.C) if c != 0.0),
                   tuple(zip(rows, (float(b) for b in design.B), strict=True)))  # fmt: skip


def filter_correct(terms: FilterTerms, x: list[Value], measured_rad_s: Value) -> list[Value]:
    """x̂[k|k] = x̂[k|k−1] + L (y[k] − C x̂[k|k−1]).

    ``x`` is the state as a list of m entries, each a float (one filter) or an array of shape
    (N,) (N filters, one per element, as ``cartctl tune --robust`` runs them); so is the result.
    """
    innovation = measured_rad_s
    for j, c in terms.C:
        innovation = innovation - c * x[j]
    return [xi + li * innovation for xi, li in zip(x, terms.L, strict=True)]


def filter_predict(terms: FilterTerms, x: list[Value], voltage_v: Value) -> list[Value]:
    """x̂[k+1|k] = A x̂[k|k] + B u[k], on a state as :func:`filter_correct` takes it."""
    new = []
    for row, b in terms.AB:  # plain loops: a generator per row costs more than the sums
        acc = b * voltage_v
        for j, a in row:
            acc = acc + a * x[j]
        new.append(acc)
    return new


class SteadyStateSpeedEstimator:
    """The steady-state Kalman filter: fixed gain L, plain floats, a few µs per tick.

    Parameters
    ----------
    design : KalmanDesign
        A, B, C and the steady-state filter gain L come from here.
    """

    def __init__(self, design: KalmanDesign) -> None:
        self.design = design
        self.terms = FilterTerms.from_design(design)
        """The filter :func:`filter_correct` and :func:`filter_predict` run (read only)."""
        self.reset()

    def reset(self) -> None:
        """State at rest (x̂ = 0)."""
        self._x: list[float] = [0.0] * len(self.terms.L)

    def correct(self, measured_rad_s: float) -> float:
        """x̂ += L (y − C x̂) with the speed measured at this tick (rad/s); return x̂_1 (rad/s)."""
        if math.isfinite(measured_rad_s):
            self._x = filter_correct(self.terms, self._x, float(measured_rad_s))
        return self._x[0]

    def predict(self, voltage_v: float) -> None:
        """x̂ ← A x̂ + B u with the voltage applied at this tick (V; non-finite counts as 0)."""
        u = float(voltage_v) if math.isfinite(voltage_v) else 0.0
        self._x = filter_predict(self.terms, self._x, u)

    @property
    def state(self) -> NDArray[np.float64]:
        """x̂, shape (m,) (a copy)."""
        return np.array(self._x)

    def state_values(self) -> list[float]:
        """x̂ as a list of floats, without a numpy array: the estimator's own list, not a copy
        (each step replaces it, so it holds the values of the moment it was taken)."""
        return self._x
