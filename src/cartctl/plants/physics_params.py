"""Physical parameters of the cart simulator: one motor, the whole cart, and the shipped presets.

These are plain frozen dataclasses, read by :mod:`cartctl.plants.physics`. Every motor quantity is
given *at the wheel*: the gearbox is folded in, so the inertia, the friction torques and the torque
constant are what the wheel shaft sees, and the speed is the wheel's speed (rad/s).

The presets are calibrated, not measured. ``benchmarks/calibrate_physics.py --fit`` chooses them so
that the report's ARX fit (equation 6, nk = 2), run on the simulator's *measured* speed under the
report's square wave from a plain ``reset()``, gives back the report's θ = [c, d, a, b] (equation 8
in the air, equation 12 on the ground) within the script's tolerance (10 % of a term, or 0.03 for b
and for terms below 0.1), with a quarter weight on the spread over encoder start offsets. In the air
all θ are within tolerance from reset. On the ground they are too (worst 0.8 tolerance, motor A's
b), but ``--fit`` does not give these values: its grids over J and L alone stop at ≈ 2.3
tolerances. The ground motors' load was made mostly dry friction (viscous 6.8e-4 instead of 1.6e-3,
the rolling friction raised to keep the plateau), and the added inertia and inductance then come
from a random search. The ground point is a narrow one: from other encoder start offsets, or with J
changed by 0.5 % or L by 0.5–1 %, the fit lands several tolerances off (c and d shrink), because
the encoder's quantisation biases this ill-conditioned fit by an amount that depends on where each
stop falls between encoder edges. The script with no options checks them.

Both presets apply a command 3 ms after the tick it was given at (``actuation_delay_s = 0.003``,
one firmware timing for both): the report's cart answers about 0.7 tick sooner than microOS's
documented order (the command written at the next tick's ``io()``) implies, see
:mod:`cartctl.plants.physics`.

=============================  =========  =========  ============================================
quantity                       motor A    motor B    remark
=============================  =========  =========  ============================================
actuation_delay_s              0.003      0.003      chosen; the report's cart answers sooner
inertia_kg_m2                  8.76e-4    8.76e-4    rotor × gear ratio² plus wheel; fitted (air)
viscous_n_m_s, air             1.6e-3     1.6e-3     chosen (not identifiable from the targets)
viscous_n_m_s, ground          6.8e-4     6.8e-4     searched; more of the ground load is dry
coulomb_n_m                    0.05       0.05       chosen; breakaway ≈ 0.34 V in the air
torque_constant_n_m_a          0.4476     0.4476     from the gain; no-load ≈ 25 rad/s at 12 V
resistance_ohm                 3.0        3.0        chosen; stall ≈ 4 A and 1.8 N·m at 12 V
inductance_h, air              0.992e-3   0.928e-3   fitted (air); an *effective* lag, see below
inductance_h, ground           6.38e-3    6.38e-3    searched; an effective lag, see below
added_inertia_kg_m2, ground    6.679e-4   6.679e-4   searched; ≈ 1.26 kg cart, m r²/2, r 32.5 mm
rolling_n_m, ground            0.09023    0.09023    from the gain; breakaway ≈ 0.94 V
=============================  =========  =========  ============================================

No-load current ≈ 0.2 A. The inductances give L/R ≈ 0.3 ms in the air and 2.1 ms on the ground,
near a small motor's winding; on the ground they stand for every lag between the PWM and the wheel
torque, including the tyres' compliance and slip that the report sees as a plateau. The rolling
friction is an effective value (gearbox load losses and caster scrub included), above textbook
rolling resistance.

K and the rolling friction are set to four digits so that the 10 V plateau (9.976 V after PWM
rounding) moves a whole number of encoder counts per tick: 60 in the air, 57 on the ground. With a
fractional count, the quantisation error repeats in a pattern that the ARX fit explains with its
fast pole, which then swings by tens of percent for a 0.2 % change of K. Anything that moves the
plateau (K, the friction, the PWM rounding) needs the calibration rerun.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from types import MappingProxyType
from typing import Any

from cartctl.cart import ENCODER_COUNTS_PER_REV, PERIOD_S, PWM_STEP_V, SUPPLY_V
from cartctl.errors import InputError

__all__ = [
    "ACTUATION_MS_RANGE",
    "PRESETS",
    "CartParams",
    "MotorParams",
    "check_actuation_ms",
    "preset",
]


def _require_positive(owner: str, name: str, value: float, *, allow_zero: bool = False) -> None:
    """Raise InputError unless ``value`` is finite and positive (or zero when allowed)."""
    ok = math.isfinite(value) and (value >= 0.0 if allow_zero else value > 0.0)
    if not ok:
        expected = "a finite number ≥ 0" if allow_zero else "a finite number > 0"
        raise InputError(f"{owner}.{name} must be {expected}, got {value!r}")


@dataclass(frozen=True, slots=True)
class MotorParams:
    """One geared DC motor with its wheel, seen at the wheel shaft (report eq. 1 + dry friction).

    ``J dω/dt + b ω + τ_c sign(ω) = K i`` and ``L di/dt + R i = v − K ω``.

    Attributes
    ----------
    inertia_kg_m2 : float
        J, rotor inertia times the gear ratio squared plus the wheel's own (kg·m²).
    viscous_n_m_s : float
        b, viscous friction (N·m·s/rad).
    coulomb_n_m : float
        τ_c, Coulomb (dry) friction torque (N·m); also the breakaway torque at rest.
    torque_constant_n_m_a : float
        K, torque constant (N·m/A), equal to the back-EMF constant (V·s/rad).
    resistance_ohm : float
        R, armature resistance (Ω).
    inductance_h : float
        L, armature inductance (H).
    """

    inertia_kg_m2: float
    viscous_n_m_s: float
    coulomb_n_m: float
    torque_constant_n_m_a: float
    resistance_ohm: float
    inductance_h: float

    def __post_init__(self) -> None:
        for name in ("inertia_kg_m2", "torque_constant_n_m_a", "resistance_ohm", "inductance_h"):
            _require_positive("MotorParams", name, getattr(self, name))
        for name in ("viscous_n_m_s", "coulomb_n_m"):
            _require_positive("MotorParams", name, getattr(self, name), allow_zero=True)


@dataclass(frozen=True, slots=True)
class CartParams:
    """The whole cart: two motors, the ground load, the firmware's limits and the sensor.

    Attributes
    ----------
    name : str
        A label (the preset name, or anything for a custom cart).
    motor_a, motor_b : MotorParams
        The two motors (each with its own constants).
    added_inertia_kg_m2 : float
        Inertia the cart body adds to each wheel when it drives on the ground (kg·m²); 0 in the air.
        The two wheels are not coupled through the chassis (the report models each motor alone).
    rolling_n_m : float
        Rolling resistance torque at each wheel on the ground (N·m), added to the motor's Coulomb
        friction (so it also resists breakaway); 0 in the air.
    supply_v : float
        Supply voltage (V); commands saturate at ± this.
    pwm_step_v : float
        Resolution of the applied voltage (V); the firmware rounds to the nearest step (ties to
        even), never beyond the supply.
    counts_per_rev : int
        Encoder counts per wheel revolution.
    period_s : float
        Control tick period (s).
    substeps : int
        Integration substeps per tick. The integration is exact for any number: a substep is only
        the window in which a stop is looked for (a speed that crossed zero and back within one
        would be missed), so it must stay short against the motor's time constants.
    noise_std_rad_s : float
        Standard deviation of white Gaussian noise added to each measured speed (rad/s); 0 = off.
    actuation_delay_s : float or None
        Time from the tick at which a command is given to the moment it drives the motor (s), a
        whole number of substeps in [0, period_s]. None is one period: microOS's documented order,
        where the next tick's ``io()`` writes the command. The presets carry a calibrated, shorter
        value (see the module docstring).
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
        for name in ("supply_v", "pwm_step_v", "period_s"):
            _require_positive("CartParams", name, getattr(self, name))
        for name in ("added_inertia_kg_m2", "rolling_n_m", "noise_std_rad_s"):
            _require_positive("CartParams", name, getattr(self, name), allow_zero=True)

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
        """The actuation delay (s): ``actuation_delay_s``, or one period when that is None."""
        if self.actuation_delay_s is None:
            return self.period_s
        return float(self.actuation_delay_s)

    def to_dict(self) -> dict[str, Any]:
        """The parameters as plain JSON-ready values (motors as nested dicts)."""
        return asdict(self)

    def with_actuation_ms(self, actuation_ms: float) -> CartParams:
        """Return a copy whose commands land ``actuation_ms`` after their tick (see :func:`check_actuation_ms`).

        The substeps are refined (to 0.1 ms) when the delay is not a whole number of them.
        """
        delay_s = check_actuation_ms(actuation_ms) / 1000.0
        substeps = self.substeps
        for candidate in (self.substeps, 2 * self.substeps, 5 * self.substeps, 10 * self.substeps):
            n = delay_s / self.period_s * candidate
            if abs(n - round(n)) < 1e-6:
                substeps = candidate
                break
        return replace(self, actuation_delay_s=delay_s, substeps=substeps)

    def with_noise(self, noise_std_rad_s: float) -> CartParams:
        """Return a copy with another measurement noise level (rad/s standard deviation)."""
        return replace(self, noise_std_rad_s=noise_std_rad_s)


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


ACTUATION_MS_RANGE = (0.0, 10.0)
"""``actuation_ms`` lies in (0, 10] ms: after its tick, within the tick (10: the next ``io()``)."""
ACTUATION_MS_STEP = 0.1
"""``actuation_ms`` is given to this resolution (ms)."""


def check_actuation_ms(value: float | str) -> float:
    """``value`` (ms) if it is a valid actuation timing; else a one-line :class:`InputError`.

    A command lands ``actuation_ms`` after the tick it was given at: 3 is the presets' calibrated
    timing (the report's cart), 10 microOS's documented order (the next tick's ``io()``).
    """
    low, high = ACTUATION_MS_RANGE
    try:
        ms = float(value)
    except (TypeError, ValueError):
        raise InputError(f"actuation_ms needs a number of ms in (0, 10], got {value!r}") from None
    if math.isnan(ms):
        raise InputError("actuation_ms must be a number of ms, got nan")
    if not (math.isfinite(ms) and low < ms <= high):
        raise InputError(
            f"actuation_ms must be in (0, 10] ms (3: the calibrated timing, 10: the next io()), "
            f"got {value}"
        )
    steps = ms / ACTUATION_MS_STEP
    if abs(steps - round(steps)) > 1e-6:
        raise InputError(f"actuation_ms is taken to 0.1 ms, got {value}")
    return ms


def preset(name: str) -> CartParams:
    """Return the preset called ``name``.

    Raises
    ------
    InputError
        If there is no such preset; the message lists the valid names.
    """
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        valid = ", ".join(sorted(PRESETS))
        raise InputError(f"unknown physics preset {name!r}; expected one of: {valid}") from None
