"""Kalman speed estimators for the loop: the fixed-gain one, and one for timing noise.

Per tick ``correct(y[k])`` then ``predict(u[k])`` on a :class:`KalmanDesign` (state x =
[x_1 … x_n, b], x_1 the speed in rad/s, b an input disturbance in V)::

    correct:  x̂[k|k]   = x̂[k|k−1] + L (y[k] − C x̂[k|k−1])    returns x̂_1[k|k]
    predict:  x̂[k+1|k] = A x̂[k|k] + B u[k]

x̂_1[k|k] estimates the *measured* speed (the last tick's average); the mean of it and
x̂_1[k+1|k] the true speed at tick k (:mod:`cartctl.design.kalman`). A non-finite measurement is
skipped and a non-finite voltage counts as 0 V (what the cart applies).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from cartctl.runtime.elementwise import Value


@dataclass(frozen=True, eq=False)
class KalmanDesign:
    """A steady-state Kalman filter for the speed: m = n + 1 states with the bias, else
    n = ``n_model_states``. A (m, m), B (m,) (0 in the bias row), C (m,); Q (m, m) the process
    noise per tick (σ_w² B_x B_xᵀ, σ_b² on the bias), R the measurement variance ((rad/s)²), P the
    a-priori DARE solution and L = P Cᵀ (C P Cᵀ + R)⁻¹. Noise levels: σ_w (V), σ_b (V per tick),
    √R (rad/s: quantisation plus ``design --measurement-noise``), σ_ε (ticks,
    :class:`KalmanSpeedEstimator`; P and L stay those of Q).
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

    @property
    def has_bias(self) -> bool:
        return self.A.shape[0] > self.n_model_states

    def _closed(self) -> NDArray[np.float64]:
        return np.eye(self.A.shape[0]) - np.outer(self.L, self.C)

    def posterior_covariance(self) -> NDArray[np.float64]:
        """Steady-state a posteriori covariance P[k|k] = (I − L C) P."""
        return self._closed() @ self.P

    def poles(self) -> NDArray[np.complex128]:
        """Estimator poles: eigenvalues of (I − L C) A, sorted by magnitude."""
        eig = np.linalg.eigvals(self._closed() @ self.A)
        return np.array(sorted(eig.astype(complex), key=lambda p: (abs(p), p.imag)))

    def to_dict(self) -> dict[str, object]:
        """JSON form: the matrices as nested lists, the noise levels and ``estimator_poles``."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        return {
            **{k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in out.items()},
            "has_bias": self.has_bias,
            "estimator_poles": [[float(p.real), float(p.imag)] for p in self.poles()],
        }


class KalmanSpeedEstimator:
    """The Kalman filter with its covariance propagated, for a design with timing noise: a
    command change Δu landing ε ticks early or late acts as an input −ε Δu, so ``predict``
    propagates P with Q + (σ_ε Δu[k])² B Bᵀ (u[−1] = 0 after a reset); ``correct`` uses
    L[k] = P Cᵀ / (C P Cᵀ + R) and P − L[k] C P.
    """

    def __init__(self, design: KalmanDesign) -> None:
        self.design = design
        self._BB = np.outer(design.B, design.B)
        self._AT = np.ascontiguousarray(design.A.T)
        self.reset()

    def reset(self) -> None:
        self._x = np.zeros(self.design.A.shape[0])
        self._P = np.array(self.design.P, dtype=float)
        self.gain = np.array(self.design.L, dtype=float)  # the latest L[k]
        self._last_voltage_v = 0.0

    def correct(self, measured_rad_s: float) -> float:
        if math.isfinite(measured_rad_s):
            d = self.design
            PC = self._P @ d.C
            s = float(PC @ d.C) + d.R
            self.gain = PC / s
            self._x += self.gain * (float(measured_rad_s) - float(self._x @ d.C))
            self._P -= np.outer(PC, PC) / s  # symmetric, as P
        return float(self._x[0])

    def predict(self, voltage_v: float) -> None:
        d = self.design
        u = float(voltage_v) if math.isfinite(voltage_v) else 0.0
        extra = (d.timing_noise_std_ticks * (u - self._last_voltage_v)) ** 2
        self._last_voltage_v = u
        self._x = d.A @ self._x + d.B * u
        self._P = d.A @ self._P @ self._AT + d.Q
        if extra > 0.0:
            self._P += extra * self._BB

    @property
    def state(self) -> NDArray[np.float64]:
        return self._x.copy()


class FilterTerms(NamedTuple):
    """A fixed-gain filter as floats without its zeros: L, C's (index, value) entries, and per
    state A's row of (column, value) entries with B's entry."""

    L: tuple[float, ...]
    C: tuple[tuple[int, float], ...]
    AB: tuple[tuple[tuple[tuple[int, float], ...], float], ...]

    @classmethod
    def from_design(cls, design: KalmanDesign) -> FilterTerms:
        """The terms of ``design`` (the observer form has at most three entries per row of A)."""

        def nonzero(values: NDArray[np.float64]) -> tuple[tuple[int, float], ...]:
            return tuple((j, float(v)) for j, v in enumerate(values) if v != 0.0)

        AB = tuple(zip(map(nonzero, design.A), map(float, design.B), strict=True))
        return cls(tuple(map(float, design.L)), nonzero(design.C), AB)


def filter_correct(terms: FilterTerms, x: list[Value], measured_rad_s: Value) -> list[Value]:
    """``correct`` on a state of m entries, floats or arrays."""
    innovation = measured_rad_s
    for j, c in terms.C:
        innovation = innovation - c * x[j]
    return [xi + li * innovation for xi, li in zip(x, terms.L, strict=True)]


def filter_predict(terms: FilterTerms, x: list[Value], voltage_v: Value) -> list[Value]:
    """``predict`` on a state as :func:`filter_correct` takes it."""
    new = []
    for row, b in terms.AB:  # plain loops: a generator per row costs more than the sums
        acc = b * voltage_v
        for j, a in row:
            acc = acc + a * x[j]
        new.append(acc)
    return new


class SteadyStateSpeedEstimator:
    """The steady-state Kalman filter: fixed gain L, plain floats, a few µs per tick."""

    def __init__(self, design: KalmanDesign) -> None:
        self.design = design
        self.terms = FilterTerms.from_design(design)
        self.reset()

    def reset(self) -> None:
        self._x: list[float] = [0.0] * len(self.terms.L)

    def correct(self, measured_rad_s: float) -> float:
        if math.isfinite(measured_rad_s):
            self._x = filter_correct(self.terms, self._x, float(measured_rad_s))
        return self._x[0]

    def predict(self, voltage_v: float) -> None:
        u = float(voltage_v) if math.isfinite(voltage_v) else 0.0
        self._x = filter_predict(self.terms, self._x, u)

    @property
    def state(self) -> NDArray[np.float64]:
        return np.array(self._x)

    def state_values(self) -> list[float]:
        """x̂ as the estimator's own list (each step replaces it)."""
        return self._x
