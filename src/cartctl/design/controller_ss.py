"""A controller file's ``[motors.X]`` entry read back (checked), and the controller as the loop
runs it, built once as a linear state space from (r, y) to u: for the loop analysis, the
pole-placement C(z) of the files, the check of a file's C(z) against its gains and ``export --mat``.

Unsaturated and with the estimator's steady-state gain L, every controller of cartctl is LTI::

    s[k+1] = A s[k] + B [r[k], y[k]]ᵀ,     u[k] = C s[k] + D [r[k], y[k]]ᵀ

(r the reference and y the measured speed, rad/s; u in V), the states in the tick order of
:mod:`cartctl.runtime.base` (correct, compute u, predict), e = r − y, x̂[k|k] = x̂ + L (y − C x̂):

- PI on the measurement: s = [I[k−1]] (V), I[k] = I[k−1] + Ki·Ts·e[k], u[k] = Kp·e[k] + I[k].
- PI on the Kalman estimate: s = [x̂[k|k−1] (m states), I[k−1]], e = r − x̂_1[k|k].
- Pole placement: s = [x̂[k|k−1], x_i]; u = Kr·r − K·x̂[k|k] − Ki·x_i, x_i⁺ = x_i + Ts (r − y)
  (no x_i without Ki, the integral action being the disturbance estimate).

The feedback part C_fb(z) = −U(z)/Y(z) (r = 0) closes the loop as L = C_fb·G·z^(−extra).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import MISSING, dataclass, fields
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.pi import pi_tf_coeffs
from cartctl.design.request import MAX_TIMING_NOISE_TICKS, RANGES
from cartctl.runtime.kalman import KalmanDesign
from cartctl.runtime.statefeedback import FeedbackGains

COVARIANCE_BOUND = 1e6  # largest covariance entry (rad²/s², V²) of a file; designs hold below 1
CONSISTENCY_RTOL = 1e-6  # a stored C(z) against its gains', relative to the largest coefficient
_KALMAN_ARRAYS = ("A", "B", "C", "Q", "P", "L")


def kalman_from_entry(entry: Mapping[str, Any]) -> KalmanDesign:
    """Rebuild a :class:`KalmanDesign` from a file's ``estimator`` table; KeyError for a missing
    key, ValueError naming what does not fit."""
    values: dict[str, Any] = {}
    for f in fields(KalmanDesign):
        if f.name not in entry:
            if f.default is not MISSING:  # a newer field (timing_noise_std_ticks): its default
                continue
            raise KeyError(f"estimator.{f.name}")
        value = entry[f.name]
        try:
            values[f.name] = np.asarray(value, dtype=float) if f.name in _KALMAN_ARRAYS else value
        except (TypeError, ValueError):  # numpy's words: 'an inhomogeneous shape', 'convert'
            raise ValueError(f"estimator.{f.name} must be numbers in rows of one length") from None
    # shapes that fit together, finite numbers, covariances, and an error that decays
    A = values["A"]
    m = A.shape[0] if A.ndim == 2 else -1
    shapes = {"A": (m, m), "B": (m,), "C": (m,), "L": (m,), "Q": (m, m), "P": (m, m)}
    for name, shape in shapes.items():
        array = values[name]
        if m < 1 or array.shape != shape:
            raise ValueError(f"estimator.{name} has shape {array.shape}; expected {shape}")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"estimator.{name} holds a value that is not a finite number")
    r = float(values["R"])
    if not (math.isfinite(r) and 0.0 < r <= COVARIANCE_BOUND):
        raise ValueError(f"estimator.R must be a variance in (0, {COVARIANCE_BOUND:g}], got {r}")
    for name in ("Q", "P"):
        cov = values[name]
        scale = max(1.0, float(np.max(np.abs(cov))))
        if (
            np.max(np.abs(cov)) > COVARIANCE_BOUND
            or np.max(np.abs(cov - cov.T)) > 1e-9 * scale
            or np.min(np.linalg.eigvalsh((cov + cov.T) / 2.0)) < -1e-9 * scale
        ):
            raise ValueError(
                f"estimator.{name} must be a covariance: symmetric, positive semidefinite, "
                f"entries up to {COVARIANCE_BOUND:g}"
            )
    timing = values.get("timing_noise_std_ticks", 0.0)
    if not RANGES["timing_noise_std_ticks"][0](timing):
        raise ValueError(
            "estimator.timing_noise_std_ticks must be a number of ticks in "
            f"[0, {MAX_TIMING_NOISE_TICKS:g}], got {timing!r}"
        )
    design = KalmanDesign(**values)
    radius = float(np.max(np.abs(design.poles())))
    if not radius < 1.0:
        raise ValueError(
            f"the estimator's error does not decay (its poles reach |z| = {radius:.4g}); "
            "redesign the controller"
        )
    return design


@dataclass(frozen=True)
class _Gains:  # a FeedbackGains read back from a file
    K: NDArray[np.float64]
    Ki: float
    Kr: float
    period_s: float
    estimator: KalmanDesign


def feedback_gains(entry: Mapping[str, Any], period_s: float) -> _Gains:
    """A pole-placement entry's K, Ki, Kr and estimator; KeyError, TypeError or ValueError for a
    missing gain or one that is not a number."""
    kalman = kalman_from_entry(entry["estimator"])
    try:
        k = np.asarray(entry["K"], dtype=float).ravel()
        ki, kr = float(entry["Ki"]), float(entry["Kr"])
    except (TypeError, ValueError):
        raise ValueError("K (a list), Ki and Kr must be numbers") from None
    return _Gains(k, ki, kr, float(period_s), kalman)


@dataclass(frozen=True, eq=False)
class ControllerStateSpace:
    """A discrete controller ``s⁺ = A s + B [r, y]ᵀ``, ``u = C s + D [r, y]ᵀ`` (the module's);
    ``states`` names each state, e.g. ``('xhat_1', 'xhat_2', 'bias_v', 'integral_v')``."""

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    D: NDArray[np.float64]
    period_s: float
    states: tuple[str, ...]

    def feedback_response(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """C_fb(z) = −U(z)/Y(z) with r = 0, at the points ``z`` (complex, any shape)."""
        z = np.asarray(z, dtype=complex)
        flat, n = z.ravel(), self.A.shape[0]
        # (z I − A) X = B_y for every z at once: a stack of n×n systems
        lhs = flat[:, None, None] * np.eye(n) - self.A[None, :, :]
        rhs = np.broadcast_to(self.B[:, 1].astype(complex), (flat.size, n))[..., None]
        x = np.linalg.solve(lhs, rhs)[..., 0]
        return -(x @ self.C[0] + self.D[0, 1]).reshape(z.shape)

    def feedback_tf(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """C_fb(z) as (num, den), descending powers of z, den monic (common roots not cancelled)."""
        import scipy.signal

        num, den = scipy.signal.ss2tf(self.A, self.B[:, 1:2], -self.C, -self.D[:, 1:2])
        num = np.atleast_1d(np.squeeze(num))
        return num / den[0], den / den[0]


def controller_state_space(
    method: str, entry: Mapping[str, Any], period_s: float
) -> ControllerStateSpace:
    """The linear controller of one motor's ``[motors.X]`` entry (``kp``, ``ki`` and an optional
    ``estimator`` for a PI; ``K``, ``Ki``, ``Kr`` and ``estimator`` for pole placement); KeyError,
    TypeError or ValueError for a missing gain or one that is not a number."""
    ts = float(period_s)
    if method != "pi":
        return state_feedback(feedback_gains(entry, ts))
    kp, ki = float(entry["kp"]), float(entry["ki"])
    g, q = kp + ki * ts, ki * ts  # u = g·e + I[k−1], I[k] = I[k−1] + q·e
    est = entry.get("estimator")
    if est is None:  # no x̂: e = r − y
        none = SimpleNamespace(A=np.zeros((0, 0)), B=np.zeros(0), C=np.zeros(0), L=np.zeros(0))
        return _law(ts, none, g, np.zeros(0), ky=g, integrator=(1.0, q, 0.0, q, "integral_v"))
    arrays = {k: np.asarray(est[k], dtype=float) for k in ("A", "B", "C", "L")}
    x = SimpleNamespace(**arrays, n_model_states=est.get("n_model_states", len(arrays["B"])))
    return _law(ts, x, g, x.C, gain=g, integrator=(1.0, q, q, 0.0, "integral_v"))


def state_feedback(design: FeedbackGains) -> ControllerStateSpace:
    """Pole placement's controller (see the module docstring) from its gains: a fresh
    :class:`~cartctl.design.poles.PolesDesign` or a file's, read back."""
    est = design.estimator
    k = np.zeros(est.A.shape[0])
    k[: design.K.size] = design.K
    ki, ts = float(design.Ki), float(design.period_s)
    integrator = None if ki == 0.0 else (-ki, ts, 0.0, ts, "integral_rad")
    return _law(ts, est, float(design.Kr), k, integrator=integrator)


def _law(
    ts: float,
    est: Any,
    kr: float,
    k: NDArray[np.float64],
    *,
    gain: float = 1.0,
    ky: float = 0.0,
    integrator: tuple[float, float, float, float, str] | None = None,
) -> ControllerStateSpace:
    """u = kr·r − gain·k·x̂[k|k] − ky·y + ci·s on the estimator ``est`` (its A, B, C, L and
    n_model_states), x̂[k|k] = (I − L C) x̂ + L y, x̂⁺ = A x̂[k|k] + B u, and with ``integrator``
    = (ci, ar, ax, ay, name) the state s⁺ = s + ar·r − ax·k·x̂[k|k] − ay·y."""
    a, b, c, el = est.A, est.B, est.C, est.L
    m = a.shape[0]
    lc = np.eye(m) - np.outer(el, c)
    klc, kl = k @ lc, float(k @ el)
    n = m + (integrator is not None)
    big_a, big_b, big_c = np.zeros((n, n)), np.zeros((n, 2)), np.zeros((1, n))
    big_a[:m, :m] = a @ lc - gain * np.outer(b, klc)
    big_b[:m, 0] = kr * b
    big_b[:m, 1] = a @ el - (gain * kl + ky) * b
    big_c[0, :m] = -gain * klc
    big_d = np.array([[kr, -(gain * kl + ky)]])
    n_x = min(int(getattr(est, "n_model_states", 0)), m)  # xhat_i (rad/s), then bias_v (V)
    names = [f"xhat_{i + 1}" for i in range(n_x)] + ["bias_v"] * (m - n_x)
    if integrator is not None:
        ci, ar, ax, ay, name = integrator
        big_a[:m, m] = ci * b
        if ax:
            big_a[m, :m] = -ax * klc
        big_a[m, m] = 1.0
        big_b[m] = [ar, -(ax * kl + ay)]
        big_c[0, m] = ci
        names.append(name)
    return ControllerStateSpace(big_a, big_b, big_c, big_d, ts, tuple(names))


def feedback_tf_coeffs(design: FeedbackGains) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Pole placement's C_fb(z) = −U/Y as (num, den), descending powers of z, den monic, minimal
    (common roots cancelled to 1e-9): the ``controller_num``/``controller_den`` of its files."""
    import control

    num, den = state_feedback(design).feedback_tf()
    # a transfer-function minreal: the state-space one needs slycot
    tf = control.tf(num, den, design.period_s).minreal(tol=1e-9)
    num = np.atleast_1d(np.squeeze(tf.num[0][0]))
    den = np.atleast_1d(np.squeeze(tf.den[0][0]))
    return num / den[0], den / den[0]


def _coeffs(values: Iterable[Any]) -> str:
    shown = [
        f"{v:.10g}" if isinstance(v, int | float) and not isinstance(v, bool) else repr(v)
        for v in values
    ]
    return "[" + ", ".join(shown) + "]"


def _disagrees(stored: Any, expected: NDArray[np.float64]) -> bool:
    """True unless ``stored`` is a list of numbers equal to ``expected`` (see CONSISTENCY_RTOL)."""
    try:
        got = np.asarray(stored, dtype=float)
    except (TypeError, ValueError):
        return True
    if got.shape != expected.shape or not np.all(np.isfinite(got)):
        return True
    scale = float(np.max(np.abs(expected))) if expected.size else 0.0
    return bool(np.any(np.abs(got - expected) > CONSISTENCY_RTOL * scale))


def consistency_problems(controller: Any) -> list[str]:
    """Where a file's stored C(z) disagrees with the one its gains give (for pole placement the
    feedback C_fb: Kr acts on the reference), one sentence per key; an entry without C(z), or
    with gains that are missing or not numbers, is left to ``build_controllers``."""
    problems: list[str] = []
    ts = controller.period_s
    for motor, entry in controller.motors.items():
        if "controller_num" not in entry and "controller_den" not in entry:
            continue
        try:
            if controller.method == "pi":
                kp, ki = float(entry["kp"]), float(entry["ki"])
                num, den = pi_tf_coeffs(kp, ki, ts)
                source = (f"Kp = {kp:.10g}, Ki = {ki:.10g} and Ts = {ts:g} s give "
                          "(C(z) = Kp + Ki·Ts·z/(z−1))")  # fmt: skip
            else:
                num, den = feedback_tf_coeffs(feedback_gains(entry, ts))
                source = f"K, Ki, the estimator and Ts = {ts:g} s give"
        except (KeyError, TypeError, ValueError, IndexError, np.linalg.LinAlgError):
            continue
        for key, expected in (("controller_num", num), ("controller_den", den)):
            stored = entry.get(key)
            if _disagrees(stored, expected):
                shown = _coeffs(stored) if isinstance(stored, list) else repr(stored)
                problems.append(
                    f"[motors.{motor}] {key} = {shown} but {source} {_coeffs(expected)}"
                )
    return problems
