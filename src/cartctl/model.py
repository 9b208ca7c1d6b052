"""ARX motor models: parameters, transfer functions, simulation, poles and zeros.

Sits at the bottom of the pipeline: ``identify`` produces these models, ``design`` and the simulated
plant consume them. Everything here is pure maths on arrays (no I/O; model files are in
:mod:`cartctl.data.modelfile`).

The model, in the report's notation for its structure (na = 2, nb = 2, nk = 2), is

    ω[k] + c ω[k−1] + d ω[k−2] = a v[k−2] + b v[k−3],      θ = [c, d, a, b]

and in general ``A(q) y[k] = B(q) u[k − nk]`` with

    A(q) = 1 + a_1 q⁻¹ + … + a_na q⁻ⁿᵃ,      B(q) = b_0 + b_1 q⁻¹ + … + b_{nb−1} q⁻⁽ⁿᵇ⁻¹⁾.

θ is ``[a_1 … a_na, b_0 … b_{nb−1}]``: the report's order and sign convention.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.cart import PERIOD_S
from cartctl.errors import InputError

RootKind = Literal["delay", "pole", "zero"]

_ORIGIN_TOL = 1e-12

MARGINAL_POLE_RADIUS = 0.99
"""A pole with |z| above this is slow or marginally stable (a time constant over 100 ticks, or
an oscillation that barely decays): ``inspect`` flags it and output-error refinement keeps its
poles within it."""


def check_extra_delay_ticks(ticks: object, name: str = "extra delay") -> int:
    """``ticks`` as a loop delay beyond a model's own: a whole number >= 0 (else InputError
    naming it as ``name``)."""
    if isinstance(ticks, bool) or not isinstance(ticks, int | np.integer) or ticks < 0:
        raise InputError(f"{name} must be a whole number >= 0 ticks, got {ticks!r}")
    return int(ticks)


def pole_damping(z: complex, period_s: float) -> tuple[float | None, float | None]:
    """Damping ratio ζ and natural frequency f_n (Hz) of a discrete root, as ``control.damp``.

    The root z of a system sampled every Ts behaves like the continuous root s = ln(z) / Ts
    (principal logarithm), so f_n = |ln z| / (2π Ts) and ζ = −Re(s) / |s| = −cos(∠ ln z). A
    negative real root lands at Im(s) = π/Ts: it alternates sign every tick. The one rule for
    ``inspect`` and ``design``.

    Parameters
    ----------
    z : complex
        The root in the z-plane.
    period_s : float
        Sample period Ts (s).

    Returns
    -------
    damping : float or None
        ζ; None where ``control.damp`` gives NaN: at z = 0 (a pure delay, ln z = −∞) and at
        z = 1 (an integrator, s = 0).
    freq_hz : float or None
        f_n (Hz); None at z = 0, where ``control.damp`` gives an infinite ωn.
    """
    z = complex(z)
    if z == 0:
        return None, None
    s = cmath.log(z)
    if s == 0:
        return None, 0.0
    return -s.real / abs(s), abs(s) / (2.0 * math.pi * period_s)


@dataclass(frozen=True, slots=True)
class Root:
    """A pole or zero of a discrete model with its continuous-time equivalent.

    Attributes
    ----------
    value : complex
        Location in the z-plane.
    kind : {'delay', 'pole', 'zero'}
        'delay' for a pole at z = 0 (a pure one-sample delay, with no frequency).
    freq_hz : float or None
        Continuous-equivalent natural frequency |ln z| / (2π Ts) in Hz (:func:`pole_damping`).
        None for z = 0.
    damping : float or None
        Damping ratio −Re(s) / |s| of s = ln(z) / Ts (:func:`pole_damping`). None for z = 0
        and z = 1.
    """

    value: complex
    kind: RootKind
    freq_hz: float | None
    damping: float | None

    def to_dict(self) -> dict[str, object]:
        """``inspect --json`` form: ``{"re", "im", "kind", "freq_hz", "damping"}``."""
        return {
            "re": float(self.value.real),
            "im": float(self.value.imag),
            "kind": self.kind,
            "freq_hz": self.freq_hz,
            "damping": self.damping,
        }


def classify_root(value: complex, kind: Literal["pole", "zero"], period_s: float) -> Root:
    """Describe a z-plane root by its continuous-equivalent frequency and damping.

    Parameters
    ----------
    value : complex
        The root in the z-plane; within 1e-12 of the origin it is taken as z = 0.
    kind : {'pole', 'zero'}
        What the root is. A pole at the origin becomes kind 'delay'.
    period_s : float
        Sample period Ts (s).

    Returns
    -------
    Root
    """
    z = complex(value)
    if abs(z) < _ORIGIN_TOL:
        return Root(0j, "delay" if kind == "pole" else "zero", None, None)
    damping, freq_hz = pole_damping(z, period_s)
    return Root(z, kind, freq_hz, damping)


def _clean_roots(coeffs: NDArray[np.float64]) -> NDArray[np.complex128]:
    """Roots of a polynomial, with conjugate pairs made exact and tiny imaginary parts removed."""
    roots = np.roots(coeffs).astype(complex)
    scale = max(1.0, float(np.max(np.abs(roots)))) if roots.size else 1.0
    roots.imag[np.abs(roots.imag) < 1e-12 * scale] = 0.0
    roots.real[np.abs(roots.real) < 1e-14 * scale] = 0.0
    return np.array(sorted(roots, key=lambda r: (abs(r), r.imag)), dtype=complex)


@dataclass(frozen=True)
class ArxModel:
    """A single-input single-output ARX model ``A(q) y[k] = B(q) u[k − nk]``.

    The attributes are named after the polynomials A (output side, the transfer function's
    denominator) and B (input side, its numerator), as in system identification and in
    :func:`scipy.signal.lfilter`'s ``(b, a)``. The report names the same four numbers
    θ = [c, d, a, b], where **a and b are both numerator coefficients**. For its structure
    (na = nb = 2, nk = 2)::

        report   Ω(z)/V(z) = (a z + b) / (z³ + c z² + d z)
        here     ar = (c, d)      b = (a, b): the report's a is b[0], its b is b[1]
                 num() = [a, b]   den() = [1, c, d, 0]   (descending powers of z, as control.tf)

    so neither of the report's a and b is in ``ar``, and ``theta`` is ``(*ar, *b)`` in the
    report's order.

    Attributes
    ----------
    ar : tuple of float
        a_1 … a_na, the output (denominator) coefficients after the leading 1. For the report's
        structure this is (c, d).
    b : tuple of float
        b_0 … b_{nb−1}, the input (numerator) coefficients: B(q), not the report's scalar b. For
        the report's structure this is (a, b).
    nk : int
        Input delay in samples (≥ 0). The report's structure has nk = 2: one sample from the
        zero-order hold and one from the firmware.
    period_s : float
        Sample period Ts (s).

    Units: u in V, y in rad/s, so the DC gain is in rad/s/V.
    """

    ar: tuple[float, ...]
    b: tuple[float, ...]
    nk: int = 2
    period_s: float = PERIOD_S

    def __post_init__(self) -> None:
        object.__setattr__(self, "ar", tuple(float(v) for v in self.ar))
        object.__setattr__(self, "b", tuple(float(v) for v in self.b))
        if not self.b:
            raise InputError("an ARX model needs at least one input coefficient (nb >= 1)")
        if not all(math.isfinite(v) for v in (*self.ar, *self.b)):
            raise InputError(f"ARX coefficients must be finite, got ar={self.ar}, b={self.b}")
        if not isinstance(self.nk, int | np.integer) or self.nk < 0:
            raise InputError(f"input delay nk must be a whole number >= 0, got {self.nk!r}")
        object.__setattr__(self, "nk", int(self.nk))
        if not (math.isfinite(self.period_s) and self.period_s > 0.0):
            raise InputError(
                f"sample period must be a positive number of seconds, got {self.period_s}"
            )

    def with_extra_delay(self, ticks: int) -> ArxModel:
        """This model with ``ticks`` more ticks of input delay (nk + d): a loop that much slower.

        Raises
        ------
        InputError
            ``ticks`` is not a whole number >= 0.
        """
        return ArxModel(self.ar, self.b, self.nk + check_extra_delay_ticks(ticks), self.period_s)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_theta(
        cls, theta: ArrayLike, *, na: int = 2, nb: int = 2, nk: int = 2, period_s: float = PERIOD_S
    ) -> ArxModel:
        """Build from θ = [a_1 … a_na, b_0 … b_{nb−1}] (the report's [c, d, a, b] for na = nb = 2)."""
        values = np.asarray(theta, dtype=float).ravel()
        if values.size != na + nb:
            raise InputError(
                f"theta has {values.size} values, but na={na} and nb={nb} need {na + nb}"
            )
        return cls(tuple(values[:na]), tuple(values[na:]), nk, period_s)

    @classmethod
    def from_tf(
        cls, num: Sequence[float], den: Sequence[float], *, period_s: float = PERIOD_S
    ) -> ArxModel:
        """Build from a transfer function in descending powers of z (as python-control takes it).

        ``den`` must be monic (leading 1). The delay nk is the relative degree. Roots at the origin
        (trailing zeros) are absorbed into the delay, as in ``(a z + b) / (z³ + c z² + d z)``.
        """
        num_arr = np.trim_zeros(np.asarray(num, dtype=float), "f")
        den_arr = np.trim_zeros(np.asarray(den, dtype=float), "f")
        if num_arr.size == 0 or den_arr.size == 0:
            raise InputError("numerator and denominator must have a non-zero coefficient")
        if den_arr[0] != 1.0:
            raise InputError(f"denominator must be monic (leading coefficient 1), got {den_arr[0]}")
        nk = den_arr.size - num_arr.size
        if nk < 0:
            raise InputError(
                "the transfer function is improper (numerator degree above denominator's)"
            )
        ar = np.trim_zeros(den_arr, "b")[1:]
        return cls(tuple(ar), tuple(np.trim_zeros(num_arr, "b")), nk, period_s)

    # -- shapes -------------------------------------------------------------------------------
    @property
    def na(self) -> int:
        """Number of output (denominator) coefficients."""
        return len(self.ar)

    @property
    def nb(self) -> int:
        """Number of input (numerator) coefficients."""
        return len(self.b)

    @property
    def theta(self) -> NDArray[np.float64]:
        """θ = [a_1 … a_na, b_0 … b_{nb−1}], shape (na + nb,)."""
        return np.array((*self.ar, *self.b), dtype=float)

    @property
    def order(self) -> int:
        """Degree n of the denominator in z: max(na, nk + nb − 1)."""
        return max(self.na, self.nk + self.nb - 1)

    def num(self) -> NDArray[np.float64]:
        """Numerator in descending powers of z, leading zeros trimmed (``[a, b]`` for the report).

        It is z^(n − nk) B(z⁻¹): trailing zeros appear when na > nk + nb − 1.
        """
        return np.concatenate([self.b, np.zeros(self.order - self.nk - self.nb + 1)])

    def den(self) -> NDArray[np.float64]:
        """Denominator in descending powers of z (``[1, c, d, 0]`` for the report's structure)."""
        den = np.zeros(self.order + 1)
        den[0] = 1.0
        den[1 : self.na + 1] = self.ar
        return den

    def response_at(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """G(z) = num(z) / den(z) (rad/s per V) at the points ``z``; at z = exp(j 2π f Ts), the
        frequency response at f Hz."""
        return np.polyval(self.num(), z) / np.polyval(self.den(), z)

    def lfilter_coeffs(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(b, a) in powers of q⁻¹ for :func:`scipy.signal.lfilter`: b = [0]*nk + b, a = [1, ar]."""
        b = np.concatenate([np.zeros(self.nk), self.b])
        a = np.concatenate([[1.0], self.ar])
        return b, a

    # -- LTI views ----------------------------------------------------------------------------
    def to_tf(self):
        """The model as a python-control discrete transfer function (dt = Ts)."""
        import control

        return control.tf(self.num(), self.den(), dt=self.period_s)

    def poles(self) -> list[Root]:
        """Poles with their continuous-equivalent frequencies; those at z = 0 are 'delay'."""
        return [classify_root(p, "pole", self.period_s) for p in _clean_roots(self.den())]

    def zeros(self) -> list[Root]:
        """Zeros (finite roots of the numerator) with their continuous-equivalent frequencies."""
        return [classify_root(z, "zero", self.period_s) for z in _clean_roots(self.num())]

    def dc_gain(self) -> float:
        """Static gain B(1) / A(1) in output units per input unit (rad/s/V); inf at an integrator."""
        a_sum = 1.0 + sum(self.ar)
        b_sum = sum(self.b)
        if a_sum == 0.0:
            return math.inf if b_sum != 0.0 else math.nan
        return b_sum / a_sum

    def pole_radius(self) -> float:
        """The largest pole magnitude |z| (0 for a model without poles)."""
        return max((abs(r.value) for r in self.poles()), default=0.0)

    def is_stable(self) -> bool:
        """True when every pole lies strictly inside the unit circle."""
        return self.pole_radius() < 1.0

    # -- time domain --------------------------------------------------------------------------
    def simulate(self, voltage_v: ArrayLike) -> NDArray[np.float64]:
        """Simulate the difference equation from rest.

        Parameters
        ----------
        voltage_v : array_like, shape (n,)
            Input u[k] (V), one value per tick.

        Returns
        -------
        ndarray, shape (n,)
            Output y[k] (rad/s) with zero initial conditions.
        """
        u = np.asarray(voltage_v, dtype=float)
        if u.ndim != 1:
            raise InputError(f"voltage sequence must be one-dimensional, got shape {u.shape}")
        from scipy import signal  # here, not at the top: it costs a run's start 0.8 s

        b, a = self.lfilter_coeffs()
        return signal.lfilter(b, a, u)

    def step_response(
        self, amplitude_v: float = 1.0, duration_s: float = 1.0
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Response to a step of ``amplitude_v`` applied at tick 0.

        Returns
        -------
        time_s : ndarray, shape (n,)
            Tick times (s), n = round(duration_s / Ts) + 1.
        speed_rad_s : ndarray, shape (n,)
        """
        n = round(duration_s / self.period_s) + 1
        if n < 2:
            raise InputError(f"step duration must be at least one period, got {duration_s} s")
        time_s = np.arange(n, dtype=np.float64) * self.period_s
        return time_s, self.simulate(np.full(n, float(amplitude_v)))

    def describe(self, var: str = "z") -> str:
        """The transfer function as text, e.g. ``(0.6466 z − 0.07751) / (z³ − 0.9356 z² + 0.2173 z)``."""
        return f"({format_poly(self.num(), var)}) / ({format_poly(self.den(), var)})"


_SUPERSCRIPT = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")


def format_poly(coeffs: Sequence[float] | NDArray[np.float64], var: str = "z") -> str:
    """Format a polynomial in descending powers of ``var`` with 4 significant digits."""
    coeffs = list(coeffs)
    degree = len(coeffs) - 1
    parts: list[str] = []
    for i, c in enumerate(coeffs):
        if c == 0.0:
            continue
        power = degree - i
        mag = abs(c)
        term = "" if (mag == 1.0 and power > 0) else f"{mag:.4g}"
        if power >= 1:
            term += (
                (" " if term else "")
                + var
                + (str(power).translate(_SUPERSCRIPT) if power > 1 else "")
            )
        sign = "−" if c < 0 else "+"
        parts.append(
            term if not parts and c > 0 else (f"−{term}" if not parts else f"{sign} {term}")
        )
    return " ".join(parts) if parts else "0"
