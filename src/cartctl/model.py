"""ARX motor models (:class:`ArxModel`, u in V, y in rad/s): parameters, transfer functions,
simulation, poles and zeros (pure maths). The report's structure (na = 2, nb = 2, nk = 2) is

    ω[k] + c ω[k−1] + d ω[k−2] = a v[k−2] + b v[k−3],      θ = [c, d, a, b]
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
from cartctl.choices import is_whole
from cartctl.errors import InputError

RootKind = Literal["delay", "pole", "zero"]

MARGINAL_POLE_RADIUS = 0.99
"""A pole with |z| above this is slow or marginally stable: ``inspect`` flags it and
output-error refinement keeps its poles within it."""

UNIT_CIRCLE_TOLERANCE = 1e-9
"""A pole within this of |z| = 1 is on the unit circle (an integrator of a model file, at z = 1,
comes out of the root finder within about 1e-15): not stable (:meth:`ArxModel.stability`)."""


def check_extra_delay_ticks(ticks: object, name: str = "extra delay") -> int:
    """``ticks`` as a whole number >= 0 of extra loop delay, else InputError naming ``name``."""
    if not is_whole(ticks) or ticks < 0:
        raise InputError(f"{name} must be a whole number >= 0 ticks, got {ticks!r}")
    return int(ticks)


def check_input_delay(nk: int, where: str = "") -> None:
    """Refuse nk < 1 (the one line of design, tune and the sim plant; ``where`` prefixes it)."""
    if nk < 1:
        raise InputError(
            f"{where}the model has no input delay (nk = {nk}); a controller computes u[k] after "
            "measuring y[k], so a design or a simulated plant needs nk >= 1 (identify --delay 1 "
            "or more)"
        )


def pole_damping(z: complex, period_s: float) -> tuple[float | None, float | None]:
    """Damping ratio ζ and natural frequency f_n (Hz) of a discrete root, as ``control.damp``.

    With s = ln(z) / Ts (principal logarithm): f_n = |s| / 2π and ζ = −Re(s) / |s|; a negative
    real root has Im(s) = π/Ts. The one rule for ``inspect`` and ``design``. Returns
    (None, None) at z = 0 and (None, 0.0) at z = 1, where ``control.damp`` gives NaN or inf.
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
    """A pole or zero in the z-plane, with :func:`pole_damping`'s ``freq_hz`` and ``damping``.

    ``kind`` is 'delay' for a pole at z = 0 (a one-sample delay, no frequency).
    """

    value: complex
    kind: RootKind
    freq_hz: float | None
    damping: float | None

    def to_dict(self) -> dict[str, object]:
        """``inspect --json`` form: ``{"re", "im", "kind", "freq_hz", "damping"}``."""
        return {"re": float(self.value.real), "im": float(self.value.imag), "kind": self.kind,
                "freq_hz": self.freq_hz, "damping": self.damping}  # fmt: skip


def classify_root(value: complex, kind: Literal["pole", "zero"], period_s: float) -> Root:
    """A z-plane root as a :class:`Root`; within 1e-12 of the origin it is z = 0."""
    z = complex(value)
    if abs(z) < 1e-12:
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

    ``ar`` holds a_1 … a_na (A, the denominator, after its leading 1) and ``b`` holds
    b_0 … b_{nb−1} (B, the numerator), as :func:`scipy.signal.lfilter`'s ``(b, a)``. The
    report's θ = [c, d, a, b] has **a and b both in the numerator**::

        report   Ω(z)/V(z) = (a z + b) / (z³ + c z² + d z)
        here     ar = (c, d)      b = (a, b)
                 num() = [a, b]   den() = [1, c, d, 0]   (descending powers of z, as control.tf)

    ``nk`` is the input delay (samples, ≥ 0; 2 in the report: the zero-order hold and the
    firmware), ``period_s`` the sample period Ts (s). The DC gain is in rad/s/V.
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
        """This model with ``ticks`` (a whole number >= 0) more ticks of input delay."""
        return ArxModel(self.ar, self.b, self.nk + check_extra_delay_ticks(ticks), self.period_s)

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
        """Build from num and monic den in descending powers of z; nk is the relative degree,
        and roots at the origin (trailing zeros) go into the delay."""
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

    @property
    def na(self) -> int:
        return len(self.ar)

    @property
    def nb(self) -> int:
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
        """Numerator z^(n − nk) B(z⁻¹) in descending powers of z (``[a, b]`` for the report)."""
        return np.concatenate([self.b, np.zeros(self.order - self.nk - self.nb + 1)])

    def den(self) -> NDArray[np.float64]:
        """Denominator in descending powers of z (``[1, c, d, 0]`` for the report)."""
        return np.concatenate([[1.0], self.ar, np.zeros(self.order - self.na)])

    def response_at(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """G(z) (rad/s per V) at the points ``z``; at z = exp(j 2π f Ts), the response at f Hz."""
        return np.polyval(self.num(), z) / np.polyval(self.den(), z)

    def lfilter_coeffs(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(b, a) in powers of q⁻¹ for :func:`scipy.signal.lfilter`: b = [0]*nk + b, a = [1, ar]."""
        return np.concatenate([np.zeros(self.nk), self.b]), np.concatenate([[1.0], self.ar])

    def to_tf(self):
        """The model as a python-control discrete transfer function (dt = Ts)."""
        import control

        return control.tf(self.num(), self.den(), dt=self.period_s)

    def poles(self) -> list[Root]:
        return [classify_root(p, "pole", self.period_s) for p in _clean_roots(self.den())]

    def zeros(self) -> list[Root]:
        return [classify_root(z, "zero", self.period_s) for z in _clean_roots(self.num())]

    def dc_gain(self) -> float:
        """Static gain B(1) / A(1) (rad/s/V); inf at an integrator."""
        a_sum, b_sum = 1.0 + sum(self.ar), sum(self.b)
        if a_sum == 0.0:
            return math.inf if b_sum != 0.0 else math.nan
        return b_sum / a_sum

    def pole_radius(self) -> float:
        """The largest pole magnitude |z| (0 for a model without poles)."""
        return max((abs(r.value) for r in self.poles()), default=0.0)

    def is_stable(self) -> bool:
        """Every pole inside the unit circle (:data:`UNIT_CIRCLE_TOLERANCE` away from it)."""
        return self.pole_radius() < 1.0 - UNIT_CIRCLE_TOLERANCE

    def stability(self) -> Literal["stable", "marginally stable", "unstable"]:
        """'stable' (:meth:`is_stable`), 'marginally stable' (the other poles on the unit circle
        and simple: an integrator at z = 1, an undamped oscillation) or 'unstable' (a pole
        outside, or a repeated one on it: two closer than 1e-4)."""
        if self.is_stable():
            return "stable"
        edge = [r.value for r in self.poles() if abs(r.value) >= 1.0 - UNIT_CIRCLE_TOLERANCE]
        simple = all(abs(p - q) > 1e-4 for i, p in enumerate(edge) for q in edge[:i])
        inside = self.pole_radius() <= 1.0 + UNIT_CIRCLE_TOLERANCE
        return "marginally stable" if simple and inside else "unstable"

    def simulate(self, voltage_v: ArrayLike) -> NDArray[np.float64]:
        """The output y[k] (rad/s) from rest for the input u[k] (V), shape (n,) both."""
        u = np.asarray(voltage_v, dtype=float)
        if u.ndim != 1:
            raise InputError(f"voltage sequence must be one-dimensional, got shape {u.shape}")
        from scipy import signal  # here, not at the top: it costs a run's start 0.8 s

        return signal.lfilter(*self.lfilter_coeffs(), u)

    def step_response(
        self, amplitude_v: float = 1.0, duration_s: float = 1.0
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(time_s, speed_rad_s) for a step applied at tick 0, n = round(duration_s / Ts) + 1."""
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
    """A polynomial in descending powers of ``var``, 4 significant digits."""
    text = ""
    for power, c in zip(range(len(coeffs) - 1, -1, -1), coeffs, strict=True):
        if c == 0.0:
            continue
        term = "" if (abs(c) == 1.0 and power > 0) else f"{abs(c):.4g}"
        if power >= 1:
            exponent = str(power).translate(_SUPERSCRIPT) if power > 1 else ""
            term += (" " if term else "") + var + exponent
        sign = "−" if c < 0 else ("+" if text else "")
        text += f" {sign} {term}" if text else sign + term
    return text or "0"
