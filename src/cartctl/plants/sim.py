"""``--plant sim``: each motor runs the ARX difference equation of a model file, its nk the whole
delay from command to measurement; commands saturate at ±12 V (non-finite: 0 V), as on the cart."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import SUPPLY_V, nk_fits_loop_delay
from cartctl.errors import InputError, PlantError
from cartctl.model import ArxModel, check_input_delay
from cartctl.plants.base import Measurement
from cartctl.runtime.elementwise import Value

DIVERGED_RAD_S = 1e6
"""A simulated speed beyond this (rad/s; the cart's motors reach about 25) has run away."""


def saturate(voltage_v: float, limit_v: float = SUPPLY_V) -> float:
    """Clamp a command to ±``limit_v``; NaN or ±inf becomes 0 V (the safe value)."""
    if not math.isfinite(voltage_v):
        return 0.0
    return min(limit_v, max(-limit_v, voltage_v))


def arx_next(
    b: Sequence[float | Value], u: Sequence[Value] | NDArray[np.float64], offset: int,
    ar: Sequence[float | Value], y: Sequence[Value] | NDArray[np.float64],
) -> Value:  # fmt: skip
    """y[k+1] = Σ b_i v[k+1−nk−i] − Σ a_j y[k+1−j], the ARX difference equation; ``u`` (V) and
    ``y`` (rad/s) newest first (u[0] = v[k], y[0] = y[k]), b_0's command at ``u[offset]``,
    offset = nk − 1. Floats or arrays (:mod:`~cartctl.runtime.elementwise`)."""
    y_next: Any = 0.0  # an array after the first term, for arrays
    for i, b_i in enumerate(b):
        y_next = y_next + b_i * u[offset + i]
    for j, a_j in enumerate(ar):
        y_next = y_next - a_j * y[j]
    return y_next


class ArxPlant:
    """Two ARX motors behind the :class:`~cartctl.plants.base.Plant` interface.

    ``noise_std_rad_s``: white Gaussian measurement noise (0: off), seeded by ``seed``; commands
    saturate at ±12 V. ``loop_delay_ticks`` is the model file's (None: nk − 1).
    """

    def __init__(
        self,
        model_a: ArxModel,
        model_b: ArxModel,
        *,
        noise_std_rad_s: float = 0.0,
        seed: int | None = None,
        loop_delay_ticks: int | None = None,
    ) -> None:
        if model_a.period_s != model_b.period_s:
            raise InputError(
                f"motor models have different sample periods: {model_a.period_s} s and {model_b.period_s} s"
            )
        for motor, m in (("a", model_a), ("b", model_b)):
            check_input_delay(m.nk, f"motor {motor}'s model: ")
        if not (math.isfinite(noise_std_rad_s) and noise_std_rad_s >= 0.0):
            raise InputError(
                f"noise must be a standard deviation >= 0 rad/s, got {noise_std_rad_s}"
            )
        self.period_s = model_a.period_s
        self.models = (model_a, model_b)
        self._loop_delay_ticks = loop_delay_ticks
        self.noise_std_rad_s = float(noise_std_rad_s)
        self._rng = np.random.default_rng(seed)
        self._rest()

    @property
    def loop_delay_ticks(self) -> int:
        """Ticks from a measurement to its voltage on the motor: the model file's where every
        model's nk fits it (as ``design`` takes it), else the larger nk − 1 (a model edited to
        answer later is a longer loop, whatever its file once recorded)."""
        nk = max(m.nk for m in self.models)
        recorded = self._loop_delay_ticks
        if recorded is not None and all(nk_fits_loop_delay(m.nk, recorded) for m in self.models):
            return int(recorded)
        return nk - 1

    def _measure(self, ya: float, yb: float) -> Measurement:
        if self.noise_std_rad_s > 0.0:
            na, nb = self._rng.normal(0.0, self.noise_std_rad_s, 2)
            return Measurement(ya + float(na), yb + float(nb), ya, yb)
        return Measurement(ya, yb, ya, yb)

    def _rest(self) -> None:
        """Each motor's past commands (V) and speeds (rad/s), newest first, all zero."""
        self._u = [deque([0.0] * (m.nk + len(m.b)), maxlen=m.nk + len(m.b)) for m in self.models]
        self._y = [deque([0.0] * len(m.ar), maxlen=len(m.ar) or None) for m in self.models]

    def reset(self) -> Measurement:
        """Back to rest; the tick-0 measurement. The noise stream carries on (fresh noise for
        each experiment; the same seed and calls reproduce the same results)."""
        self._rest()
        return self._measure(0.0, 0.0)

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        """Command voltages at tick k (saturated), advance, return the tick k+1 measurement;
        PlantError once a speed passes :data:`DIVERGED_RAD_S` (an unstable model ran away)."""
        speeds, voltages = [], (voltage_a_v, voltage_b_v)
        for model, u, y, v in zip(self.models, self._u, self._y, voltages, strict=True):
            u.appendleft(saturate(v))  # u[0] = v[k], u[1] = v[k-1], ...
            speeds.append(arx_next(model.b, u, model.nk - 1, model.ar, y))
            if model.ar:
                y.appendleft(speeds[-1])
        for motor, speed in zip("ab", speeds, strict=True):
            if not abs(speed) < DIVERGED_RAD_S:
                raise PlantError(
                    f"the simulated motor {motor} ran away ({speed:.3g} rad/s): its model is "
                    "unstable"
                )
        return self._measure(speeds[0], speeds[1])

    def close(self) -> None:
        """Nothing to release; a simulated cart simply stops being stepped."""
