"""Discrete pole placement with integral action, on the observer-form realisation of a model.

Where it sits: the ``design`` stage (``cartctl design --method poles``). The result, a
:class:`PolesDesign`, carries the gains and the Kalman estimator design; the runtime's
:class:`~cartctl.runtime.statefeedback.StateFeedbackController` runs it.

The plant is the realisation x[k+1] = A x + B u, y = C x of :func:`~cartctl.design.statespace.realise`
(n states, x_1 = speed). The loop's delay is part of it: the model's nk covers one tick of loop
delay (the report's nk = 2: a voltage computed from y[k] is on the motor from tick k + 1), and
``extra_delay_ticks`` = d more ticks (3 through the PC serial loop, loop delay 4) are realised as d
more states, n = 3 + d for the report's structure. Every closed-loop pole is placed, the delay's
included: with d = 3 there are 6 (or 7) of them.

Integral action, by default from the estimator's input-disturbance state b̂ (V): the Kalman filter
of :mod:`cartctl.design.kalman` models x[k+1] = A x + B (u + b), b a slow random walk, and the
control law cancels the estimated disturbance::

    u[k] = Kr r[k] − K x̂[k|k] − b̂[k|k]          (V; then clamped to ±voltage_limit_v)

with K placing the n eigenvalues of A − B K, and Kr = 1 / (C (I − A + B K)⁻¹ B) the static gain
that makes the model's closed loop r → y exact at DC. The measured speed then has no static error
whatever the model's gain or the friction: in steady state the innovation y − C x̂ is zero, so
y = C x̂, and the model, driven by u + b̂ = Kr r − K x̂, settles at C x̂ = r. On the model itself b̂
stays at 0 and r → y is the placed loop, the reference acting at once through Kr. With the model
exact the closed loop's eigenvalues are the n placed poles and the n + 1 estimator poles
(separation); b̂'s own integrating mode is the controller's integrator, so nothing fights it.

Without the disturbance state (``bias_drift_std_v=0``) the integral is an error integrator, the
integral of the speed error, which is the wheel's angle error (rad)::

    x_i[k+1] = x_i[k] + Ts (r[k] − y[k])

    ⎡ x  ⎤        ⎡  A     0 ⎤ ⎡ x  ⎤   ⎡ B ⎤        ⎡ 0  ⎤
    ⎣ x_i⎦[k+1] = ⎣ −Ts C  1 ⎦ ⎣ x_i⎦ + ⎣ 0 ⎦ u  +   ⎣ Ts ⎦ r

    u[k] = −K x̂[k|k] − Ki x_i[k] + Kr r[k]

with [K, Ki] placing the n + 1 eigenvalues of the augmented closed loop. Ki is negative: a
positive angle error (the wheel behind) raises the voltage. The reference reaches u through the
integrator and through Kr, which multiplies the closed loop's r → y transfer by
(Kr (z − 1) − Ki Ts) / (−Ki Ts): one zero at z = 1 + Ki Ts / Kr. With Kr = 0 there is no zero;
the default, Kr = −Ki Ts, puts the zero at z = 0: every signal's response to r is advanced by
exactly one tick, with the same shape, overshoot and peak voltage. Without the disturbance state
the estimate carries the model's static error (friction is about 0.8 V on the ground), which is
why it is not the default.

Why the disturbance estimate replaces the error integrator rather than joining it, measured on
the report's ground model A for a 45 ms, 1 % specification (phase margin, gain margin, peak of
|1/(1 + L)| with the loop broken at the measurement; a 10 rad/s step on the model, and on the
physics simulator when it answered about 0.7 tick later than the model):

=====================================================  =======  =======  ====  ======  ========
integral action                                         PM       GM       Ms    model   late sim
=====================================================  =======  =======  ====  ======  ========
error integrator, no disturbance state                  56°      6.7 dB   1.91  1.2 %   32 %
error integrator, b̂ estimated but not used              40°      5.5 dB   2.24  1.2 %   49 %
error integrator and u −= b̂ (two integrators)           36°      5.1 dB   2.35  1.2 %   56 %
b̂ fed back, no error integrator (the default)           75°      12.5 dB  1.36  1.3 %   13 %
=====================================================  =======  =======  ====  ======  ========

The disturbance state costs margin as long as an error integrator stays: its integrating mode
and the integrator's act on the same low-frequency error, and feeding b̂ forward beside the
integrator makes the controller type 2. Used as the integral action, b̂ corrects only what the
model does not predict, so the placed response to the reference is untouched, and the margins are
those of a model-based (two-degree-of-freedom) loop.

Poles from a specification: ζ from the overshoot, ζ = −ln(OS) / √(π² + ln²(OS)); ω_n from the 2 %
settling time, T_s ≈ 4 / (ζ ω_n); the dominant pair s = −ζ ω_n ± j ω_n √(1 − ζ²) maps to
z = exp(s Ts). The other poles are real and fast, distinct so that ``control.place`` applies:
z_j = exp(−(ratio + j) ζ ω_n Ts), j = 0, 1, …, with ratio = ``fast_pole_ratio``. Given poles
that repeat are placed with Ackermann's formula (``control.acker``). The choice and the checks of the
poles are in :mod:`cartctl.design.pole_choice`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cartctl.design.kalman import (
    DEFAULT_BIAS_DRIFT_STD_V,
    DEFAULT_PROCESS_NOISE_STD_V,
    KalmanDesign,
    design_kalman,
)
from cartctl.design.pole_choice import check_poles, has_repeats, poles_text, spec_poles
from cartctl.design.statespace import StateSpace, realise, uncontrollable_modes
from cartctl.errors import InputError
from cartctl.model import ArxModel

__all__ = ["PolesDesign", "augment", "design_poles", "spec_poles"]

_CHECK_TOL = 1e-6
"""The placed characteristic polynomial must match the requested one to this (coefficients)."""


def augment(plant: StateSpace) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The plant with the error integrator x_i[k+1] = x_i[k] − Ts y[k] (r enters separately).

    Returns
    -------
    A_a : ndarray, shape (n + 1, n + 1)
    B_a : ndarray, shape (n + 1,)
    """
    n = plant.order
    A_a = np.zeros((n + 1, n + 1))
    A_a[:n, :n] = plant.A
    A_a[n, :n] = -plant.period_s * plant.C
    A_a[n, n] = 1.0
    return A_a, np.append(plant.B, 0.0)


@dataclass(frozen=True, eq=False)
class PolesDesign:
    """A pole-placement speed controller with integral action and its Kalman estimator.

    Attributes
    ----------
    model : ArxModel
        The model designed on.
    plant : StateSpace
        Its realisation (n states, d extra delay ticks included).
    extra_delay_ticks : int
        d, the extra loop delay designed for (ticks).
    poles : tuple of complex
        The placed closed-loop poles (z-plane), sorted by magnitude: n with the disturbance
        estimate, n + 1 with the error integrator.
    K : ndarray, shape (m,)
        Gain on the estimator's whole state x̂ (m states): V per rad/s on the n realisation
        states, then, with the disturbance state, 1 (V per V) on b̂. ``K[:n]`` is the placed
        state-feedback gain (:attr:`state_gain`).
    Ki : float
        State gain on the error integrator x_i (V per rad of angle error), u −= Ki x_i:
        negative, or 0 with the disturbance estimate; the key ``Ki`` of controller files and
        ``--json``. A state gain, so its sign is opposite to a PI's ``ki`` (u += ki ∫e).
    Kr : float
        Reference gain (V per rad/s): the static gain with the disturbance estimate; −Ki Ts, or 0
        without feedforward, with the error integrator.
    estimator : KalmanDesign
        The speed estimator, on the same realisation.
    method : {'place', 'acker'}
        How the gains were computed.
    integral : {'disturbance', 'error'}
        Where the integral action comes from: the estimator's input-disturbance state b̂ fed
        back (n placed poles, Ki = 0), or the error integrator x_i (n + 1 placed poles).
    settling_time_s, overshoot_percent : float or None
        The specification the poles came from, None when the poles were given.
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
        """Ts (s)."""
        return self.plant.period_s

    @property
    def state_gain(self) -> NDArray[np.float64]:
        """The placed gain on the n realisation states, ``K[:n]`` (V per rad/s), shape (n,)."""
        return self.K[: self.plant.order]

    def closed_loop_matrix(self) -> NDArray[np.float64]:
        """The state-feedback loop on the model; its eigenvalues are the placed poles.

        A − B K[:n], shape (n, n), with the disturbance estimate; A_a − B_a [K[:n], Ki], shape
        (n + 1, n + 1), with the error integrator.
        """
        if self.integral == "disturbance":
            return self.plant.A - np.outer(self.plant.B, self.state_gain)
        A_a, B_a = augment(self.plant)
        return A_a - np.outer(B_a, np.append(self.state_gain, self.Ki))

    def to_dict(self) -> dict[str, object]:
        """JSON form (``design --json``: ``closed_loop_poles``, ``estimator_poles`` as [re, im])."""
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
            "estimator": self.estimator.to_dict(),
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

    Give either ``poles`` or both ``settling_time_s`` and ``overshoot_percent``. With the
    estimator's input-disturbance state (``bias_drift_std_v > 0``, the default) the integral
    action is the disturbance estimate fed back and n poles are placed; without it (0) an error
    integrator is added and n + 1 poles are placed.

    Parameters
    ----------
    model : ArxModel
        Voltage (V) to speed (rad/s), nk ≥ 1.
    poles : sequence of complex, optional
        The closed-loop poles (z-plane): one per state of the realisation with the extra delay
        (3 + ``extra_delay_ticks`` for the report's structure), plus one for the error integrator
        when ``bias_drift_std_v`` is 0. Inside the unit circle; complex ones with their
        conjugates; repeats allowed (Ackermann).
    settling_time_s : float, optional
        2 % settling time of the dominant pair (s); at least as many ticks as there are poles.
    overshoot_percent : float, optional
        Overshoot of the dominant pair (%), in (0, 100).
    extra_delay_ticks : int
        Loop delay beyond the model's own (ticks), e.g. 3 for a PC-side serial loop; adds d
        states and d poles (for the report's structure).
    fast_pole_ratio : float
        In the specification mode, how many times faster (in decay rate) the first non-dominant
        pole is than the dominant pair; the next ones are ratio + 1, ratio + 2, ….
    reference_feedforward : bool
        Error integrator only: Kr = −Ki Ts (True: the response one tick sooner) or Kr = 0 (r
        through the integrator only). With the disturbance estimate Kr is always the static gain.
    process_noise_std_v, bias_drift_std_v, extra_noise_std_rad_s, timing_noise_std_ticks : float
        The estimator's noise levels (see :func:`~cartctl.design.kalman.design_kalman`);
        ``bias_drift_std_v`` also chooses the integral action (see above).

    Returns
    -------
    PolesDesign

    Raises
    ------
    InputError
        Both or neither pole modes; a bad specification; poles in the wrong number, outside the
        unit circle or without their conjugates; an uncontrollable model (a pole-zero
        cancellation, or a zero at z = 1 that no integral action can get past); a numerically
        failed placement; estimator noise levels that :func:`design_kalman` refuses.
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
    integral = "disturbance" if estimator.has_bias else "error"
    n = plant.order
    count = n if integral == "disturbance" else n + 1
    delay = f" with {extra_delay_ticks} extra delay tick(s)" if extra_delay_ticks else ""
    what = f"a model of order {model.order}{delay}" + (
        " (integral action from the disturbance estimate)"
        if integral == "disturbance"
        else " and an error integrator"
    )
    spec: tuple[float, float] | None = None  # settling time (s), overshoot (%)
    if poles is not None:
        wanted = list(poles)
    else:
        assert settling_time_s is not None and overshoot_percent is not None  # checked above
        spec = (float(settling_time_s), float(overshoot_percent))
        wanted = spec_poles(count, plant.period_s, *spec, fast_pole_ratio)
    try:
        placed = check_poles(wanted, count, what)
    except InputError as exc:  # poles given are the user's --poles
        raise InputError(f"--poles: {exc}" if poles is not None else str(exc)) from None

    A_p, B_p = (plant.A, plant.B) if integral == "disturbance" else (A_a, B_a)
    B_col = B_p.reshape(count, 1)
    if has_repeats(placed):
        method = "acker"
        gains = np.asarray(control.acker(A_p, B_col, placed), dtype=float).ravel()
    else:
        method = "place"
        gains = np.asarray(control.place(A_p, B_col, placed), dtype=float).ravel()
    A_cl = A_p - np.outer(B_p, gains)
    got, target = np.poly(A_cl), np.real(np.poly(placed))
    if not np.allclose(got, target, rtol=0.0, atol=_CHECK_TOL):
        raise InputError(
            f"pole placement is numerically ill-conditioned for poles {poles_text(placed)}: the "
            f"closed loop would have {poles_text(np.linalg.eigvals(A_cl))}; choose poles further "
            "apart or less extreme (a shorter --settling-time)"
        )
    if integral == "disturbance":
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
        integral=integral,
        settling_time_s=None if spec is None else spec[0],
        overshoot_percent=None if spec is None else spec[1],
    )
