"""Discrete pole placement with integral action, on the realisation of a model with the loop's
delay in it (:func:`~cartctl.design.kalman.realise`: n states, x_1 = speed; ``extra_delay_ticks``
= d more ticks are d more states, so every closed-loop pole is placed, the delay's included).
:class:`~cartctl.runtime.statefeedback.StateFeedbackController` runs the result.

Integral action, by default, is the estimator's input-disturbance state b̂ (V), cancelled::

    u[k] = Kr r[k] − K x̂[k|k] − b̂[k|k]          (V; then clamped to ±voltage_limit_v)

K places the n eigenvalues of A − B K; Kr = 1 / (C (I − A + B K)⁻¹ B) makes the model's r → y
exact at DC. In steady state the innovation is zero, so y = r whatever the model's gain or the
friction; the closed loop's eigenvalues are the n placed poles and the n + 1 estimator poles
(why this is the default: docs/design.md).

Without the disturbance state (``bias_drift_std_v=0``) an error integrator x_i[k+1] = x_i[k] +
Ts (r[k] − y[k]) (rad) is added and [K, Ki] place the n + 1 eigenvalues of [[A, 0], [−Ts C, 1]]
− [B; 0] [K, Ki]; u[k] = −K x̂[k|k] − Ki x_i[k] + Kr r[k], Ki < 0. Kr = −Ki Ts (the default)
puts the zero of r → y, z = 1 + Ki Ts / Kr, at z = 0 (the same response a tick sooner); Kr = 0
has none.

Poles from a specification: ζ = −ln(OS) / √(π² + ln²(OS)), ζ ω_n = 4 / T_s (2 % settling), the
dominant pair s = −ζ ω_n ± j ω_n √(1 − ζ²) mapped by z = exp(s Ts); the rest real, fast and
distinct: z_j = exp(−(ratio + j) ζ ω_n Ts), j = 0, 1, … (a loop of one pole: exp(−ζ ω_n Ts)).
Repeated poles are placed with Ackermann's formula (``control.acker``), the others with
``control.place``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cartctl.design.kalman import (
    KalmanDesign,
    StateSpace,
    design_kalman,
    realise,
    uncontrollable_modes,
)
from cartctl.design.request import DEFAULT_BIAS_DRIFT_STD_V, DEFAULT_PROCESS_NOISE_STD_V
from cartctl.errors import InputError
from cartctl.model import ArxModel


def augment(plant: StateSpace) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(A_a, B_a): the plant with the error integrator x_i[k+1] = x_i[k] − Ts y[k] (r enters
    separately), n + 1 states."""
    n = plant.order
    A_a = np.zeros((n + 1, n + 1))
    A_a[:n, :n] = plant.A
    A_a[n, :n] = -plant.period_s * plant.C
    A_a[n, n] = 1.0
    return A_a, np.append(plant.B, 0.0)


def spec_poles(
    count: int,
    period_s: float,
    settling_time_s: float,
    overshoot_percent: float,
    fast_pole_ratio: float,
) -> list[complex]:
    """The dominant pair for a settling time and overshoot, then ``count − 2`` fast real poles
    (the module docstring's rule; one pole: the pair's decay e^(−ζ ω_n Ts) alone); InputError for an overshoot outside (0, 100) %, a settling
    time under ``count`` ticks (deadbeat), a pair beyond Nyquist, or a ratio below 1."""
    os_ = float(overshoot_percent)
    if not (math.isfinite(os_) and 0.0 < os_ < 100.0):
        raise InputError(f"overshoot_percent must lie strictly between 0 and 100, got {os_}")
    ts = float(settling_time_s)
    if not (math.isfinite(ts) and ts >= count * period_s):
        raise InputError(
            f"settling_time_s must be at least {count} ticks ({count * period_s:g} s), the "
            f"deadbeat time of a loop with {count} poles; got {settling_time_s}"
        )
    ratio = float(fast_pole_ratio)
    if not (math.isfinite(ratio) and ratio >= 1.0):
        raise InputError(f"fast_pole_ratio must be a number >= 1, got {fast_pole_ratio}")
    log_os = math.log(os_ / 100.0)
    zeta = -log_os / math.hypot(math.pi, log_os)
    sigma = 4.0 / ts  # ζ ω_n (1/s)
    if count == 1:  # a first-order loop has no pair: its one pole settles like the pair's envelope
        return [complex(math.exp(-sigma * period_s))]
    omega_d = sigma / zeta * math.sqrt(1.0 - zeta * zeta)
    if omega_d * period_s >= math.pi:
        raise InputError(
            f"{os_:g} % overshoot with a {ts:g} s settling time oscillates beyond the Nyquist "
            "frequency; ask for less overshoot or a longer settling time"
        )
    pair = complex(math.exp(-sigma * period_s), 0.0) * complex(
        math.cos(omega_d * period_s), math.sin(omega_d * period_s)
    )
    fast = [complex(math.exp(-(ratio + j) * sigma * period_s)) for j in range(count - 2)]
    return [pair, pair.conjugate(), *fast]


def _check_poles(poles: Sequence[complex], count: int, what: str) -> list[complex]:
    """The poles with exact conjugate pairs, sorted; InputError for the wrong number, one not
    finite or not inside the unit circle, or a complex one without its conjugate."""
    p = [complex(v) for v in poles]
    for v in p:  # before the real ones are made exact: infj is no tiny imaginary part
        if not (math.isfinite(v.real) and math.isfinite(v.imag)):
            raise InputError(f"pole {v} is not a finite number")
    p = [complex(v.real, 0.0) if abs(v.imag) <= 1e-12 * max(1.0, abs(v)) else v for v in p]
    if len(p) != count:
        raise InputError(f"{what} needs {count} closed-loop poles, got {len(p)}")
    for v in p:
        if abs(v) >= 1.0:
            raise InputError(
                f"pole {v:.6g} lies on or outside the unit circle (|z| = {abs(v):.6g}); a stable "
                "discrete loop needs |z| < 1"
            )
    upper = sorted((v for v in p if v.imag > 0.0), key=lambda v: (v.real, v.imag))
    lower = sorted((v.conjugate() for v in p if v.imag < 0.0), key=lambda v: (v.real, v.imag))
    if len(upper) != len(lower) or any(
        abs(a - b) > 1e-9 * max(1.0, abs(a)) for a, b in zip(upper, lower, strict=True)
    ):
        raise InputError(
            f"complex poles must come in conjugate pairs, got {[f'{v:.6g}' for v in p]}"
        )
    out = [v for v in p if v.imag == 0.0]
    for v in upper:
        out += [v, v.conjugate()]
    return sorted(out, key=lambda v: (abs(v), v.imag))


def _poles_text(poles: Sequence[complex] | NDArray[np.inexact]) -> str:
    """Poles on one line: ``0.999998, 0.5±0.2j``."""
    parts = []
    for p in poles:
        z = complex(p)
        if abs(z.imag) < 1e-9:
            parts.append(f"{z.real:.6g}")
        elif z.imag > 0:
            parts.append(f"{z.real:.6g}±{z.imag:.3g}j")
    return ", ".join(parts)


@dataclass(frozen=True, eq=False)
class PolesDesign:
    """A pole-placement speed controller and its Kalman estimator, on the model's realisation
    ``plant`` (n states, the extra delay included). ``poles``: the placed closed-loop poles (z),
    n with the disturbance estimate (``integral`` 'disturbance', Ki = 0), n + 1 with the error
    integrator ('error'). ``K`` (m,) acts on the estimator's whole state x̂ (V per rad/s, then 1
    on b̂); ``Ki`` on x_i (V/rad, negative: the opposite sign of a PI's ``ki``); ``Kr`` (V per
    rad/s) on r. ``method`` is 'place' or 'acker'.
    """

    model: ArxModel
    plant: StateSpace
    extra_delay_ticks: int
    poles: tuple[complex, ...]
    K: NDArray[np.float64]
    Ki: float
    Kr: float
    estimator: KalmanDesign
    method: str
    integral: str = "error"
    settling_time_s: float | None = None
    overshoot_percent: float | None = None

    @property
    def period_s(self) -> float:
        return self.plant.period_s

    def closed_loop_matrix(self) -> NDArray[np.float64]:
        """The state-feedback loop on the model, whose eigenvalues are the placed poles:
        A − B K[:n], or A_a − B_a [K[:n], Ki] with the error integrator."""
        gain = self.K[: self.plant.order]
        if self.integral == "disturbance":
            return self.plant.A - np.outer(self.plant.B, gain)
        A_a, B_a = augment(self.plant)
        return A_a - np.outer(B_a, np.append(gain, self.Ki))

    def to_dict(self) -> dict[str, object]:
        """``design --json``'s entry of the design (poles as [re, im]; the estimator is the file's)."""
        return {
            "method": "poles",
            "Ts": self.period_s,
            "model_num": self.model.num().tolist(),
            "model_den": self.model.den().tolist(),
            "extra_delay_ticks": self.extra_delay_ticks,
            "K": self.K.tolist(),
            "Ki": self.Ki,
            "Kr": self.Kr,
            "gain_method": self.method,
            "integral_action": self.integral,
            "settling_time_s": self.settling_time_s,
            "overshoot_percent": self.overshoot_percent,
            "closed_loop_poles": [[float(p.real), float(p.imag)] for p in self.poles],
            "estimator_poles": [[float(p.real), float(p.imag)] for p in self.estimator.poles()],
        }


def design_poles(
    model: ArxModel,
    *,
    poles: Sequence[complex] | None = None,
    settling_time_s: float | None = None,
    overshoot_percent: float | None = None,
    extra_delay_ticks: int = 0,
    fast_pole_ratio: float = 4.0,
    reference_feedforward: bool = True,
    process_noise_std_v: float = DEFAULT_PROCESS_NOISE_STD_V,
    bias_drift_std_v: float = DEFAULT_BIAS_DRIFT_STD_V,
    extra_noise_std_rad_s: float = 0.0,
    timing_noise_std_ticks: float = 0.0,
) -> PolesDesign:
    """Place the closed-loop poles of a speed loop with integral action (module docstring).

    Give either ``poles`` (z; one per realisation state, plus one for the error integrator when
    ``bias_drift_std_v`` is 0; conjugate pairs) or both ``settling_time_s`` (2 %, s) and
    ``overshoot_percent`` of the dominant pair. ``reference_feedforward`` chooses Kr = −Ki Ts
    over 0 with the error integrator; the noise levels are
    :func:`~cartctl.design.kalman.design_kalman`'s. InputError for a request it cannot meet
    (bad poles or specification, an uncontrollable model, a failed placement).
    """
    import control

    from_spec = settling_time_s is not None or overshoot_percent is not None
    if (poles is None) == (not from_spec) or (
        from_spec and (settling_time_s is None or overshoot_percent is None)
    ):
        raise InputError(
            "give either poles or both settling_time_s and overshoot_percent (not both, not "
            f"neither); got poles={poles}, settling_time_s={settling_time_s}, "
            f"overshoot_percent={overshoot_percent}"
        )
    plant = realise(model, extra_delay_ticks=extra_delay_ticks)
    A_a, B_a = augment(plant)  # either integral action needs this pair controllable
    bad = uncontrollable_modes(A_a, B_a)
    if bad:
        raise InputError(
            f"the model {model.describe()} cannot be controlled with integral action: mode(s) "
            f"{[f'{v:.4g}' for v in bad]} cannot be moved (a pole-zero cancellation, or a zero at "
            "z = 1)"
        )
    estimator = design_kalman(
        plant,
        process_noise_std_v=process_noise_std_v,
        bias_drift_std_v=bias_drift_std_v,
        extra_noise_std_rad_s=extra_noise_std_rad_s,
        timing_noise_std_ticks=timing_noise_std_ticks,
    )
    bias = estimator.has_bias  # the disturbance estimate is the integral action
    n = plant.order
    count = n if bias else n + 1
    delay = f" with {extra_delay_ticks} extra delay tick(s)" if extra_delay_ticks else ""
    what = f"a model of order {model.order}{delay}" + (
        " (integral action from the disturbance estimate)" if bias else " and an error integrator"
    )
    if poles is not None:
        try:
            placed = _check_poles(poles, count, what)
        except InputError as exc:  # the user's --poles
            raise InputError(f"--poles: {exc}") from None
    else:
        assert settling_time_s is not None and overshoot_percent is not None  # checked above
        settling_time_s, overshoot_percent = float(settling_time_s), float(overshoot_percent)
        wanted = spec_poles(
            count, plant.period_s, settling_time_s, overshoot_percent, fast_pole_ratio
        )
        placed = _check_poles(wanted, count, what)

    A_p, B_p = (plant.A, plant.B) if bias else (A_a, B_a)
    repeats = any(
        abs(a - b) <= 1e-8 * max(1.0, abs(a))  # repeated: ``place`` cannot take them
        for i, a in enumerate(placed)
        for b in placed[i + 1 :]
    )
    method = "acker" if repeats else "place"
    place = control.acker if repeats else control.place
    gains = np.asarray(place(A_p, B_p.reshape(count, 1), placed), dtype=float).ravel()
    A_cl = A_p - np.outer(B_p, gains)
    got, target = np.poly(A_cl), np.real(np.poly(placed))
    if not np.allclose(got, target, rtol=0.0, atol=1e-6):  # the characteristic polynomials
        raise InputError(
            f"pole placement is numerically ill-conditioned for poles {_poles_text(placed)}: the "
            f"closed loop would have {_poles_text(np.linalg.eigvals(A_cl))}; choose poles further "
            "apart or less extreme (a shorter --settling-time)"
        )
    if bias:
        # u = Kr r − K x̂ − b̂: the model's closed loop C (I − A + B K)⁻¹ B Kr has unit DC gain
        dc = float(plant.C @ np.linalg.solve(np.eye(n) - A_cl, plant.B))
        K = np.append(gains, 1.0)
        Ki, Kr = 0.0, 1.0 / dc  # dc ≠ 0: a zero at z = 1 was refused above
    else:
        K = gains[:-1]
        Ki = float(gains[-1])
        Kr = -Ki * plant.period_s if reference_feedforward else 0.0
    K.setflags(write=False)
    return PolesDesign(
        model=model,
        plant=plant,
        extra_delay_ticks=int(extra_delay_ticks),
        poles=tuple(placed),
        K=K,
        Ki=Ki,
        Kr=Kr,
        estimator=estimator,
        method=method,
        integral="disturbance" if bias else "error",
        settling_time_s=settling_time_s,
        overshoot_percent=overshoot_percent,
    )
