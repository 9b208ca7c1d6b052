"""The physical simulator's parameters (every motor quantity at the wheel) and its presets.

The presets are calibrated, not measured (docs/plants.md: values, origin, limits);
``benchmarks/calibrate_physics.py`` checks that the report's ARX fit on their speed gives back
the report's θ. K and the rolling friction have four digits so that the 10 V plateau moves a whole
number of encoder counts per tick (60 in the air, 57 on the ground): whatever moves the plateau
(K, the friction, the PWM rounding) needs the calibration rerun.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from types import MappingProxyType
from typing import Any

from cartctl.cart import ENCODER_COUNTS_PER_REV, PERIOD_S, PWM_STEP_V, SUPPLY_V
from cartctl.errors import InputError


def _require_positive(owner: object, names: tuple[str, ...], *, allow_zero: bool = False) -> None:
    for name in names:
        value = getattr(owner, name)
        if not (math.isfinite(value) and (value >= 0.0 if allow_zero else value > 0.0)):
            expected = "a finite number ≥ 0" if allow_zero else "a finite number > 0"
            raise InputError(f"{type(owner).__name__}.{name} must be {expected}, got {value!r}")


@dataclass(frozen=True, slots=True)
class MotorParams:
    """One geared DC motor with its wheel, at the wheel shaft (the equations in
    :mod:`cartctl.plants.physics`): J (kg·m², rotor times the gear ratio squared plus the wheel),
    b (N·m·s/rad), τ_c (N·m, also the breakaway torque), K (N·m/A = V·s/rad), R (Ω), L (H).
    """

    inertia_kg_m2: float
    viscous_n_m_s: float
    coulomb_n_m: float
    torque_constant_n_m_a: float
    resistance_ohm: float
    inductance_h: float

    def __post_init__(self) -> None:
        positive = ("inertia_kg_m2", "torque_constant_n_m_a", "resistance_ohm", "inductance_h")
        _require_positive(self, positive)
        _require_positive(self, ("viscous_n_m_s", "coulomb_n_m"), allow_zero=True)


@dataclass(frozen=True, slots=True)
class CartParams:
    """The whole cart: two motors, the ground load, the firmware's limits and the sensor.

    ``added_inertia_kg_m2`` (each wheel's share of the body, uncoupled as in the report) and
    ``rolling_n_m`` (added to each motor's Coulomb friction) are 0 in the air; commands saturate
    at ±``supply_v``, rounded to the nearest ``pwm_step_v``; ``actuation_delay_s``, from a
    command's tick to the motor, is a whole number of substeps in [0, period_s] (None: one period).
    """

    name: str
    motor_a: MotorParams
    motor_b: MotorParams
    added_inertia_kg_m2: float = 0.0
    rolling_n_m: float = 0.0
    supply_v: float = SUPPLY_V
    pwm_step_v: float = PWM_STEP_V
    counts_per_rev: int = ENCODER_COUNTS_PER_REV
    period_s: float = PERIOD_S
    substeps: int = 10
    noise_std_rad_s: float = 0.0
    actuation_delay_s: float | None = None

    def __post_init__(self) -> None:
        _require_positive(self, ("supply_v", "pwm_step_v", "period_s"))
        zero_or_more = ("added_inertia_kg_m2", "rolling_n_m", "noise_std_rad_s")
        _require_positive(self, zero_or_more, allow_zero=True)
        for name in ("counts_per_rev", "substeps"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise InputError(f"CartParams.{name} must be an integer ≥ 1, got {value!r}")
        delay = self.actuation_delay()
        substeps = delay / self.period_s * self.substeps
        if not (0.0 <= delay <= self.period_s and abs(substeps - round(substeps)) < 1e-6):
            raise InputError(
                f"CartParams.actuation_delay_s must be a whole number of substeps "
                f"({self.period_s / self.substeps:g} s) in [0, {self.period_s:g}] s, got {delay!r}"
            )

    def actuation_delay(self) -> float:
        """``actuation_delay_s``, or one period when that is None (s)."""
        return self.period_s if self.actuation_delay_s is None else float(self.actuation_delay_s)

    def to_dict(self) -> dict[str, Any]:
        """The parameters as plain JSON-ready values (motors as nested dicts)."""
        return asdict(self)

    def with_actuation_ms(self, actuation_ms: float) -> CartParams:
        """A copy whose commands land ``actuation_ms`` after their tick, with the substeps refined
        (to 0.1 ms) when the delay is not a whole number of them."""
        delay_s = check_actuation_ms(actuation_ms) / 1000.0
        for substeps in (self.substeps * k for k in (1, 2, 5, 10)):
            n = delay_s / self.period_s * substeps
            if abs(n - round(n)) < 1e-6:
                return replace(self, actuation_delay_s=delay_s, substeps=substeps)
        return replace(self, actuation_delay_s=delay_s)


_AIR_A = MotorParams(8.76e-4, 1.6e-3, 0.05, 0.4476, 3.0, 0.992e-3)
_AIR_B = MotorParams(8.76e-4, 1.6e-3, 0.05, 0.4476, 3.0, 0.928e-3)

PRESETS: MappingProxyType[str, CartParams] = MappingProxyType(
    {
        "air": CartParams(name="air", motor_a=_AIR_A, motor_b=_AIR_B, actuation_delay_s=0.003),
        "ground": CartParams(
            name="ground",
            motor_a=replace(_AIR_A, viscous_n_m_s=6.8e-4, inductance_h=6.38e-3),
            motor_b=replace(_AIR_B, viscous_n_m_s=6.8e-4, inductance_h=6.38e-3),
            added_inertia_kg_m2=6.679e-4,
            rolling_n_m=0.09023,
            actuation_delay_s=0.003,
        ),
    }
)
"""The shipped presets by name (read-only): ``air`` (cart held up) and ``ground`` (driving)."""


def check_actuation_ms(value: float | str) -> float:
    """``value`` (ms) if it is a valid actuation timing, in (0, 10] to 0.1 ms; else InputError."""
    try:
        ms = float(value)
    except (TypeError, ValueError):
        raise InputError(f"actuation_ms needs a number of ms in (0, 10], got {value!r}") from None
    if math.isnan(ms):
        raise InputError("actuation_ms must be a number of ms, got nan")
    if not (math.isfinite(ms) and 0.0 < ms <= 10.0):
        raise InputError(
            f"actuation_ms must be in (0, 10] ms (3: the calibrated timing, 10: the next io()), "
            f"got {value}"
        )
    if abs(ms * 10.0 - round(ms * 10.0)) > 1e-6:
        raise InputError(f"actuation_ms is taken to 0.1 ms, got {value}")
    return ms


def preset(name: str) -> CartParams:
    """The preset called ``name``; InputError listing the valid names if there is none."""
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        valid = ", ".join(sorted(PRESETS))
        raise InputError(f"unknown physics preset {name!r}; expected one of: {valid}") from None
