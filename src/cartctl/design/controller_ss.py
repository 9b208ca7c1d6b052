"""A controller as the loop runs it, as one linear state-space system from (r, y) to u.

Where it sits: between a controller (a fresh design, or a file's ``[motors.X]`` entry) and what
needs it whole: the pole-placement ``controller_num``/``controller_den`` of its files and its
margins (:func:`feedback_tf_coeffs`), the check that a file's stored C(z) agrees with its gains
(:func:`consistency_problems`), the loop broken at the plant input
(:mod:`cartctl.design.sensitivity`) and ``cartctl export --mat`` (:mod:`cartctl.export.mat`).
The one place the controller is built as an LTI system. Pure: no I/O.

Unsaturated and with the estimator's steady-state gain L (the gain the time-varying filter of the
designs starts at and keeps), every controller of cartctl is linear time-invariant::

    s[k+1] = A s[k] + B [r[k], y[k]]ᵀ,     u[k] = C s[k] + D [r[k], y[k]]ᵀ

with r the speed reference (rad/s), y the measured speed (rad/s), u the voltage (V). The states,
in the tick order of :mod:`cartctl.runtime.base` (correct, compute u, predict):

- PI on the measurement: s = [I[k−1]], the integral term (V): I[k] = I[k−1] + Ki·Ts·e[k],
  u[k] = Kp·e[k] + I[k], e = r − y (:mod:`cartctl.runtime.pi`).
- PI on the Kalman estimate: s = [x̂[k|k−1] (m states), I[k−1]]; the PI's e = r − x̂_1[k|k], with
  x̂[k|k] = x̂ + L (y − C x̂), and the estimator predicts with u.
- Pole placement: s = [x̂[k|k−1] (m states), x_i]; u = Kr·r − K·x̂[k|k] − Ki·x_i, x_i⁺ = x_i +
  Ts (r − y) (:mod:`cartctl.runtime.statefeedback`). Without Ki (integral action from the
  disturbance estimate) x_i does not reach u and is left out.

The feedback part C_fb(z) = −U(z)/Y(z) (r = 0) closes the loop as L = C_fb·G·z^(−extra) with
negative feedback; for the PI on the measurement it is the PI's C(z) = Kp + Ki·Ts·z/(z − 1).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.entries import feedback_gains
from cartctl.design.pi import pi_tf_coeffs
from cartctl.runtime.statefeedback import FeedbackGains

__all__ = [
    "ControllerStateSpace",
    "consistency_problems",
    "controller_state_space",
    "feedback_tf_coeffs",
    "state_feedback",
]


@dataclass(frozen=True, eq=False)
class ControllerStateSpace:
    """A discrete controller ``s⁺ = A s + B [r, y]ᵀ``, ``u = C s + D [r, y]ᵀ`` (see the module).

    Attributes
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, 2)
        Columns: reference r (rad/s), measured speed y (rad/s).
    C : ndarray, shape (1, n)
    D : ndarray, shape (1, 2)
        Voltage (V) per rad/s of r and of y.
    period_s : float
        Sample period Ts (s).
    states : tuple of str
        What each state is, e.g. ``('xhat_1', 'xhat_2', 'bias', 'integral_v')``.
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    D: NDArray[np.float64]
    period_s: float
    states: tuple[str, ...]

    def feedback_response(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """C_fb(z) = −U(z)/Y(z) with r = 0, at the points ``z`` (complex, any shape)."""
        z = np.asarray(z, dtype=complex)
        n = self.A.shape[0]
        flat = z.ravel()
        # (z I − A) X = B_y for every z at once: a stack of n×n systems
        lhs = flat[:, None, None] * np.eye(n) - self.A[None, :, :]
        rhs = np.broadcast_to(self.B[:, 1].astype(complex), (flat.size, n))[..., None]
        x = np.linalg.solve(lhs, rhs)[..., 0]
        out = x @ self.C[0] + self.D[0, 1]
        return -out.reshape(z.shape)

    def feedback_tf(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """C_fb(z) as (num, den), descending powers of z, den monic (common roots not cancelled)."""
        import scipy.signal

        num, den = scipy.signal.ss2tf(self.A, self.B[:, 1:2], -self.C, -self.D[:, 1:2])
        num = np.atleast_1d(np.squeeze(num))
        return num / den[0], den / den[0]


def controller_state_space(
    method: str, entry: Mapping[str, Any], period_s: float
) -> ControllerStateSpace:
    """The linear controller of one motor's ``[motors.X]`` entry (see the module docstring).

    Parameters
    ----------
    method : {'pi', 'poles'}
    entry : mapping
        ``kp``, ``ki`` (and an optional ``estimator`` table) for a PI; ``K``, ``Ki``, ``Kr`` and
        ``estimator`` for pole placement, as a controller file holds them.
    period_s : float
        Sample period Ts (s).

    Raises
    ------
    KeyError, TypeError, ValueError
        The entry misses a gain or holds something that is not a number.
    """
    ts = float(period_s)
    est = entry.get("estimator")
    if method == "pi":
        kp, ki = float(entry["kp"]), float(entry["ki"])
        if est is None:
            g, q = kp + ki * ts, ki * ts
            return ControllerStateSpace(
                np.array([[1.0]]),
                np.array([[q, -q]]),
                np.array([[1.0]]),
                np.array([[g, -g]]),
                ts,
                ("integral_v",),
            )
        return _pi_on_estimate(kp, ki, ts, est)
    return state_feedback(feedback_gains(entry, ts))


def _estimator(est: Mapping[str, Any]) -> tuple[NDArray[np.float64], ...]:
    a = np.asarray(est["A"], dtype=float)
    b = np.asarray(est["B"], dtype=float)
    c = np.asarray(est["C"], dtype=float)
    gain = np.asarray(est["L"], dtype=float)
    return a, b, c, gain


def _state_names(n: int, m: int) -> list[str]:
    """xhat_1 … xhat_n (rad/s) of m estimator states, then bias_v (V) for the disturbance state."""
    return [f"xhat_{i + 1}" for i in range(min(n, m))] + ["bias_v"] * (m - n)


def _pi_on_estimate(
    kp: float, ki: float, ts: float, est: Mapping[str, Any]
) -> ControllerStateSpace:
    a, b, c, gain = _estimator(est)
    m = a.shape[0]
    g, q = kp + ki * ts, ki * ts
    lc = np.eye(m) - np.outer(gain, c)
    c1 = c @ lc  # x̂_1[k|k] = c1 x̂ + cl y
    cl = float(c @ gain)
    big_a = np.zeros((m + 1, m + 1))
    big_a[:m, :m] = a @ lc - g * np.outer(b, c1)
    big_a[:m, m] = b
    big_a[m, :m] = -q * c1
    big_a[m, m] = 1.0
    big_b = np.zeros((m + 1, 2))
    big_b[:m, 0] = g * b
    big_b[:m, 1] = a @ gain - g * cl * b
    big_b[m] = [q, -q * cl]
    big_c = np.zeros((1, m + 1))
    big_c[0, :m] = -g * c1
    big_c[0, m] = 1.0
    big_d = np.array([[g, -g * cl]])
    states = (*_state_names(int(est.get("n_model_states", m)), m), "integral_v")
    return ControllerStateSpace(big_a, big_b, big_c, big_d, ts, states)


def state_feedback(design: FeedbackGains) -> ControllerStateSpace:
    """Pole placement's controller (see the module docstring) from its gains: a fresh
    :class:`~cartctl.design.poles.PolesDesign` or a file's, read back."""
    est = design.estimator
    a, b, c, gain = est.A, est.B, est.C, est.L
    m = a.shape[0]
    k_full = np.zeros(m)
    k_full[: design.K.size] = design.K
    ki, kr, ts = float(design.Ki), float(design.Kr), float(design.period_s)
    lc = np.eye(m) - np.outer(gain, c)
    kl = float(k_full @ gain)
    n = m + 1 if ki != 0.0 else m
    big_a = np.zeros((n, n))
    big_a[:m, :m] = a @ lc - np.outer(b, k_full @ lc)
    big_b = np.zeros((n, 2))
    big_b[:m, 0] = kr * b
    big_b[:m, 1] = a @ gain - kl * b
    big_c = np.zeros((1, n))
    big_c[0, :m] = -(k_full @ lc)
    big_d = np.array([[kr, -kl]])
    states = _state_names(est.n_model_states, m)
    if n > m:
        big_a[:m, m] = -ki * b
        big_a[m, m] = 1.0
        big_b[m] = [ts, -ts]
        big_c[0, m] = -ki
        states.append("integral_rad")
    return ControllerStateSpace(big_a, big_b, big_c, big_d, ts, tuple(states))


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


CONSISTENCY_RTOL = 1e-6
"""How far a stored C(z) coefficient may be from the one its gains give, relative to the largest
coefficient of that polynomial (a file rounds nothing: the rest is floating-point noise)."""


def _coeffs(values: Iterable[Any]) -> str:
    """Coefficients for a message; an entry that is not a number is shown as it is."""
    return (
        "["
        + ", ".join(
            f"{v:.10g}" if isinstance(v, int | float) and not isinstance(v, bool) else repr(v)
            for v in values
        )
        + "]"
    )


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


def expected_tf(
    controller: Any, entry: Mapping[str, Any]
) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """C(z) as one motor's gains give it: (num, den, what it was computed from).

    PI: C(z) = Kp + Ki·Ts·z/(z − 1), num = [Kp + Ki·Ts, −Kp], den = [1, −1]. Pole placement: the
    feedback from the measured speed to the voltage through the estimator, integrator and K
    (:func:`cartctl.design.controller_ss.feedback_tf_coeffs`; Kr acts on the reference and is not in it).

    Raises
    ------
    KeyError, TypeError, ValueError
        The entry lacks a gain or holds something that is not a number.
    """
    ts = controller.period_s
    if controller.method == "pi":
        kp, ki = float(entry["kp"]), float(entry["ki"])
        num, den = pi_tf_coeffs(kp, ki, ts)
        return (
            num,
            den,
            f"Kp = {kp:.10g}, Ki = {ki:.10g} and Ts = {ts:g} s give (C(z) = Kp + Ki·Ts·z/(z−1))",
        )
    num, den = feedback_tf_coeffs(feedback_gains(entry, ts))
    return num, den, f"K, Ki, the estimator and Ts = {ts:g} s give"


def consistency_problems(controller: Any) -> list[str]:
    """Where a file's stored C(z) disagrees with its gains, one sentence per key.

    A motor entry without ``controller_num``/``controller_den`` (pole-placement files of older
    cartctl) has nothing to disagree with; an entry whose gains are missing or not numbers is left
    to :func:`build_controllers`, which names the problem.
    """
    problems: list[str] = []
    for motor, entry in controller.motors.items():
        if "controller_num" not in entry and "controller_den" not in entry:
            continue
        try:
            num, den, source = expected_tf(controller, entry)
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
