"""The physical cart simulator: two DC motors with friction, driven and sensed like the real cart.

Not linear, unlike the ARX plant: per motor, at the wheel (report eq. 1 plus dry friction)::

    J dω/dt + b ω + τ_c sign(ω) = K i          L di/dt + R i = v − K ω

Zero volts brakes (the H-bridge shorts the terminals: ``v = 0``, not ``i = 0``). The speed of tick
k is the whole-count encoder difference between ticks k−1 and k times ``(2π/1792) / Ts``. A
command is saturated to ±12 V, rounded to the nearest 12/255 V PWM step, and lands
``CartParams.actuation_delay_s`` after its tick (docs/plants.md), so the loop delay is one tick.

With v and the friction torque held, (i, ω, θ) is linear: each substep applies the exact
zero-order-hold map (a matrix exponential, computed once). When ω reaches zero inside a substep,
or a stuck wheel's drive torque passes τ_c, the closed-form 2×2 exponential and Newton's method
find the crossing: friction events are exact in time, without chattering around zero speed.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
from scipy.linalg import expm

from cartctl.errors import InputError
from cartctl.plants.base import Measurement
from cartctl.plants.physics_params import CartParams, MotorParams, preset
from cartctl.plants.sim import saturate


@functools.lru_cache(maxsize=64)
def _substep_map(
    a11: float, a12: float, a21: float, a22: float, L: float, J: float, h: float
) -> tuple[float, ...]:
    """The exact substep map's 12 entries the hot loop uses (cached: most of a plant's build)."""
    M = np.zeros((5, 5))  # (i, ω, θ, v, τ)
    M[0, :2], M[1, :2], M[2, 1], M[0, 3], M[1, 4] = (a11, a12), (a21, a22), 1.0, 1.0 / L, -1.0 / J
    rows, cols = (0, 0, 1, 1, 2, 2, 0, 1, 2, 0, 1, 2), (0, 1, 0, 1, 0, 1, 3, 3, 3, 4, 4, 4)
    return tuple(float(e) for e in expm(M * h)[rows, cols])


class _Wheel:
    """One wheel: state (i [A], ω [rad/s], θ [rad]), held inputs v [V] and friction torque τ [N·m]
    (positive against positive ω); with both held, ``d(i, ω)/dt = A (i, ω) + g``."""

    def __init__(
        self, motor: MotorParams, added_inertia_kg_m2: float, rolling_n_m: float, h: float
    ) -> None:
        J = motor.inertia_kg_m2 + added_inertia_kg_m2
        K, R, L = motor.torque_constant_n_m_a, motor.resistance_ohm, motor.inductance_h
        b = motor.viscous_n_m_s
        self.J, self.K, self.R, self.b, self.rl = J, K, R, b, R / L
        self.tc = motor.coulomb_n_m + rolling_n_m
        self.a11, self.a12, self.a21, self.a22 = -R / L, -K / L, K / J, -b / J
        self.det = (R * b + K * K) / (L * J)
        self.half_tr = 0.5 * (self.a11 + self.a22)
        substep = _substep_map(self.a11, self.a12, self.a21, self.a22, L, J, h)
        self.fast = (*substep, K, self.tc, R, h, math.exp(-h * R / L))

    def flow(
        self, i: float, w: float, th: float, v: float, tau: float, t: float
    ) -> tuple[float, float, float]:
        """Exact state after ``t`` seconds with v and τ held (closed-form 2×2 exponential)."""
        K, R = self.K, self.R
        den = K * K + R * self.b  # the steady state (i_eq, ω_eq) of these inputs
        i_eq = (self.b * v + K * tau) / den
        w_eq = (K * v - R * tau) / den
        y0, y1 = i - i_eq, w - w_eq
        m = self.half_tr
        disc = m * m - self.det
        if disc > 1e-12 * m * m:
            q = math.sqrt(disc)
            c, s = math.cosh(q * t), math.sinh(q * t) / q
        elif disc < -1e-12 * m * m:
            q = math.sqrt(-disc)
            c, s = math.cos(q * t), math.sin(q * t) / q
        else:
            c, s = 1.0, t
        e = math.exp(m * t)
        z0 = e * (c * y0 + s * ((self.a11 - m) * y0 + self.a12 * y1))
        z1 = e * (c * y1 + s * (self.a21 * y0 + (self.a22 - m) * y1))
        # θ gains ∫ω = ω_eq t + [A⁻¹ (e^{At} − I) y]_ω
        th += w_eq * t + (-self.a21 * (z0 - y0) + self.a11 * (z1 - y1)) / self.det
        return i_eq + z0, w_eq + z1, th

    def relax(self, i: float, v: float, t: float) -> float:
        """The current of a stuck wheel (ω = 0) after ``t`` seconds at voltage v (A)."""
        i_rest = v / self.R
        return i_rest + (i - i_rest) * math.exp(-self.rl * t)

    def event(
        self, i: float, w: float, th: float, v: float, t_end: float
    ) -> tuple[float, float, float]:
        """Run ``t_end`` seconds from (i, ω, θ), resolving each stop, stick and breakaway exactly."""
        K, tc = self.K, self.tc
        i_rest = v / self.R  # the current a stuck wheel relaxes to
        t0 = 0.0
        for _ in range(4):  # a stop, a breakaway, a stop again: more cannot fit in a substep
            span = t_end - t0
            if w == 0.0:
                if abs(K * i) <= tc:  # stuck until the drive torque passes τ_c
                    if abs(K * i_rest) <= tc:
                        return self.relax(i, v, span), 0.0, th
                    i_edge = math.copysign(tc / K, i_rest)
                    t_break = math.log((i - i_rest) / (i_edge - i_rest)) / self.rl
                    if t_break >= span:
                        return self.relax(i, v, span), 0.0, th
                    i, t0, span = i_edge, t0 + t_break, span - t_break
                    s = 1.0 if i_rest > 0.0 else -1.0
                else:
                    s = 1.0 if K * i > 0.0 else -1.0
            else:
                s = 1.0 if w > 0.0 else -1.0
            tau = s * tc
            i1, w1, th1 = self.flow(i, w, th, v, tau, span)
            if w1 * s > 0.0:
                return i1, w1, th1
            t = self._stop_time(i, w, v, tau, s, span, w1)
            if t is None:  # a start too brief to resolve: the wheel stays put
                return self.relax(i, v, span), 0.0, th
            i, _, th = self.flow(i, w, th, v, tau, t)
            w, t0 = 0.0, t0 + t
        return self.relax(i, v, t_end - t0), 0.0, th

    def _stop_time(
        self, i: float, w: float, v: float, tau: float, s: float, span: float, w_end: float
    ) -> float | None:
        """When ω, moving in direction s from w or from rest, is back at zero (s), given ``w_end``
        after ``span`` s: Newton's method in a shrinking bracket; None if it never visibly moves."""

        def along(t: float) -> tuple[float, float]:  # (ω, dω/dt) in direction s
            i_t, w_t, _ = self.flow(i, w, 0.0, v, tau, t)
            return w_t * s, (self.K * i_t - self.b * w_t - tau) / self.J * s

        lo, f_lo, hi, f_hi = 0.0, w * s, span, w_end * s
        if w == 0.0:  # leaving rest: bracket the first moving sample and the next stopped one
            for k in range(1, 16):
                f = along(span * k / 16)[0]
                if f > 0.0 and f_lo <= 0.0:
                    lo, f_lo = span * k / 16, f
                elif f <= 0.0 and f_lo > 0.0:
                    hi, f_hi = span * k / 16, f
                    break
            if f_lo <= 0.0:
                return None
        t = lo + (hi - lo) * f_lo / (f_lo - f_hi)
        for _ in range(50):
            f, slope = along(t)
            if f == 0.0:
                return t
            lo, hi = (t, hi) if f > 0.0 else (lo, t)
            newton = t - f / slope if slope != 0.0 else math.nan
            t_next = newton if lo < newton < hi else 0.5 * (lo + hi)  # nan fails the test too
            if abs(t_next - t) < 1e-13:
                return t_next
            t = t_next
        return t


def _advance(
    wheel: _Wheel, i: float, w: float, th: float, v: float, n: int
) -> tuple[float, float, float]:
    """Advance one wheel by ``n`` substeps at held voltage ``v``; return (i, ω, θ)."""
    p00, p01, p10, p11, p20, p21, gv0, gv1, gv2, gt0, gt1, gt2, K, tc, R, h, ae = wheel.fast
    i_rest = v / R  # the current a stuck wheel relaxes to
    stuck_for_good = -tc <= K * i_rest <= tc  # at rest, this voltage can never break away
    for _ in range(n):
        if w == 0.0:
            if -tc <= K * i <= tc:  # stuck: only the current moves
                if stuck_for_good or -tc <= K * (i_rest + (i - i_rest) * ae) <= tc:
                    i = i_rest + (i - i_rest) * ae
                    continue
                i, w, th = wheel.event(i, w, th, v, h)  # breaks away inside this substep
                continue
            s = 1.0 if K * i > 0.0 else -1.0
        else:
            s = 1.0 if w > 0.0 else -1.0
        tau = s * tc
        i1 = p00 * i + p01 * w + gv0 * v + gt0 * tau
        w1 = p10 * i + p11 * w + gv1 * v + gt1 * tau
        if w1 * s > 0.0 or tc == 0.0:  # moving on the same way (or no dry friction at all)
            th += p20 * i + p21 * w + gv2 * v + gt2 * tau
            i, w = i1, w1
            continue
        i, w, th = wheel.event(i, w, th, v, h)  # stops inside this substep
    return i, w, th


class PhysicsPlant:
    """A simulated cart with two physical DC motors (the module docstring has the model).

    ``cart``: a preset name or parameters; ``noise_std_rad_s`` (white, on each measured speed, its
    ``seed``'s stream not restarted by :meth:`reset`) and ``actuation_ms`` override the cart's.
    ``reversed_motors`` (e.g. ``"b"``): motors wired backwards (a positive command turns them back).
    """

    def __init__(
        self,
        cart: str | CartParams = "ground",
        *,
        noise_std_rad_s: float | None = None,
        seed: int | None = None,
        actuation_ms: float | None = None,
        reversed_motors: str = "",
    ) -> None:
        if set(reversed_motors) - {"a", "b"}:
            raise InputError(f"reversed_motors names motors a and b, got '{reversed_motors}'")
        self._sign = tuple(-1.0 if m in reversed_motors else 1.0 for m in ("a", "b"))
        params = preset(cart) if isinstance(cart, str) else cart
        if not isinstance(params, CartParams):
            raise InputError(f"cart must be a preset name or CartParams, got {type(cart).__name__}")
        if noise_std_rad_s is not None:
            params = replace(params, noise_std_rad_s=float(noise_std_rad_s))
        if actuation_ms is not None:
            params = params.with_actuation_ms(actuation_ms)
        self.params: CartParams = params
        self.period_s: float = params.period_s
        h = params.period_s / params.substeps
        load = (params.added_inertia_kg_m2, params.rolling_n_m, h)
        self._wheels = (_Wheel(params.motor_a, *load), _Wheel(params.motor_b, *load))
        self._rad_per_count = 2.0 * math.pi / params.counts_per_rev
        self._speed_per_count = self._rad_per_count / params.period_s
        self._delay_substeps = round(params.actuation_delay() / h)
        self._rng = np.random.default_rng(seed) if params.noise_std_rad_s > 0.0 else None
        limit, step = params.supply_v, params.pwm_step_v
        self._pwm = (limit, step, math.floor(limit / step + 1e-9))  # top: the last whole step
        self.applied_voltage_v: tuple[float, float]
        """The latest command, saturated and quantised (V): what the bridges hold (and report)."""
        self.last_interval_voltage_v: tuple[float, float]
        """What drove the motors in the tick just ended until the newest command landed (V)."""
        self.reset()

    loop_delay_ticks = 1
    """Ticks from a measurement to its voltage on the motor (as with microOS on the cart)."""

    def reset(self, *, position_rad: tuple[float, float] = (0.0, 0.0)) -> Measurement:
        """Both wheels at rest, no current, 0 V, at ``position_rad``; the tick-0 measurement."""
        self._state = [(0.0, 0.0, float(th)) for th in position_rad]  # (i, ω, θ) per wheel
        self._counts = [math.floor(th / self._rad_per_count) for _, _, th in self._state]
        self.applied_voltage_v = self.last_interval_voltage_v = (0.0, 0.0)
        return Measurement(0.0, 0.0, 0.0, 0.0)

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        """Command voltages (V) at this tick (landing ``actuation_delay_s`` later), advance one
        tick, and measure the next: the encoder count difference over the tick."""
        n, nd = self.params.substeps, self._delay_substeps
        commands = (self.condition_voltage(voltage_a_v), self.condition_voltage(voltage_b_v))
        speeds = []
        for m, (wheel, sign) in enumerate(zip(self._wheels, self._sign, strict=True)):
            i, w, th = _advance(wheel, *self._state[m], sign * self.applied_voltage_v[m], nd)
            if nd < n:  # the new command lands inside this tick
                i, w, th = _advance(wheel, i, w, th, sign * commands[m], n - nd)
            self._state[m] = (i, w, th)
            count = math.floor(th / self._rad_per_count)
            speeds.append((count - self._counts[m]) * self._speed_per_count)
            self._counts[m] = count
        self.last_interval_voltage_v, self.applied_voltage_v = self.applied_voltage_v, commands
        if self._rng is not None:
            noise = self._rng.standard_normal(2) * self.params.noise_std_rad_s
            speeds = [speed + float(e) for speed, e in zip(speeds, noise, strict=True)]
        return Measurement(speeds[0], speeds[1], self._state[0][1], self._state[1][1])

    def close(self) -> None:
        """Command zero volts (the motors brake); there is no resource to release."""
        self.applied_voltage_v = (0.0, 0.0)

    def condition_voltage(self, voltage_v: float) -> float:
        """What the firmware makes of a command (V): 0 if non-finite, saturated, rounded to the
        nearest PWM step (ties to even: 10 V is 212.5 steps, giving 212)."""
        limit, step, top = self._pwm
        return min(max(round(saturate(float(voltage_v), limit) / step), -top), top) * step

    @property
    def position_rad(self) -> tuple[float, float]:
        """True wheel positions (rad) since the last reset (the encoder floors these)."""
        return (self._state[0][2], self._state[1][2])

    @property
    def encoder_counts(self) -> tuple[int, int]:
        return (self._counts[0], self._counts[1])

    @property
    def armature_current_amp(self) -> tuple[float, float]:
        return (self._state[0][0], self._state[1][0])
