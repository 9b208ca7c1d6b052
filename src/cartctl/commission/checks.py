"""Commissioning's judgements, numbers in and numbers out: stage 1's wiring checks (a pulse and a
slow ramp per motor) and the excitation amplitude, stage 3's model and its verdict, stage 5's
closed-loop step against the tuning's prediction. The rules and their reasons: docs/commission.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import SUPPLY_V, encoder_quantum_rad_s
from cartctl.commission import StageError
from cartctl.data.trace import MOTORS, Trace
from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, identify
from cartctl.tune.grid import worst_metrics

PULSE_V = 4.0  # above a cart's breakaway (about 1–2 V), a third of the supply
PULSE_S = 0.2
RAMP_MAX_V = 6.0  # a wheel that has not turned by then is not working
RAMP_RATE_V_S = 4.0  # slow against the motors' time constants (tens of ms)
REST_S = 0.4
MIN_COUNTS = 3  # encoder counts a pulse must turn a wheel by to count as a motion

FULL_SCALE_FRACTION = 0.9  # of the supply, for the excitation (the controller keeps the rest)
REPORT_AMPLITUDE_V = 10.0  # the report's square-wave amplitude: where the rule starts
FRICTION_MARGIN = 3.0  # the excitation is at least this many times the larger breakaway
SPEED_SPAN = 2.0  # the excitation's steady speed is at most this many times the step


@dataclass(frozen=True)
class MotorCheck:
    """One motor's figures from the checks. ``pulse_turn_rad`` and ``other_turn_rad`` are its
    wheel's and the other wheel's rotation during its pulse (rad); ``direction`` is 'forward',
    'backward', 'crossed' (only the other encoder moved) or 'still'; ``breakaway_v`` (V) is None if
    the wheel never turned on the ramp; ``gain_rad_s_v`` is the ramp's end speed over its voltage
    above breakaway (rad/s per V)."""

    motor: str
    pulse_turn_rad: float
    other_turn_rad: float
    direction: str
    breakaway_v: float | None
    gain_rad_s_v: float | None

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if k != "motor"}


Windows = dict[tuple[str, str], slice]  # (motor, 'pulse' or 'ramp') → its ticks


def checks_sequence(period_s: float) -> tuple[NDArray[np.float64], NDArray[np.float64], Windows]:
    """The check experiment's voltages (V) per motor and its windows: rest, pulse a, rest, pulse b,
    rest, ramp a, rest, ramp b, rest."""
    rest = np.zeros(round(REST_S / period_s))
    pulse = np.full(round(PULSE_S / period_s), PULSE_V)
    ramp_ticks = round(RAMP_MAX_V / RAMP_RATE_V_S / period_s)
    ramp = np.arange(1, ramp_ticks + 1, dtype=np.float64) * (RAMP_RATE_V_S * period_s)
    volts: dict[str, list[NDArray[np.float64]]] = {m: [rest] for m in MOTORS}
    windows: Windows = {}
    for kind, shape in (("pulse", pulse), ("ramp", ramp)):
        for m in MOTORS:
            start = sum(part.size for part in volts[m])
            windows[m, kind] = slice(start, start + shape.size)
            for motor, parts in volts.items():
                parts += [shape if motor == m else np.zeros_like(shape), rest]
    return np.concatenate(volts["a"]), np.concatenate(volts["b"]), windows


def _breakaway(
    speed: NDArray[np.float64], volts: NDArray[np.float64], w: slice, loop_delay_ticks: int
) -> tuple[float | None, float | None]:
    """(breakaway V, gain rad/s/V) of a ramp; (None, None) if the wheel never turned or it is cut."""
    moving = np.abs(speed[w]) >= 0.5 * encoder_quantum_rad_s()
    runs = moving[:-2] & moving[1:-1] & moving[2:]
    if w.stop > speed.size or not runs.any():
        return None, None
    first = w.start + int(np.argmax(runs))
    at = max(w.start, first - loop_delay_ticks - 1)
    breakaway = float(volts[at])
    tail = slice(max(w.start, w.stop - 10), w.stop)
    end_v = float(np.mean(volts[tail]))
    end_speed = float(np.mean(np.abs(speed[tail])))
    gain = end_speed / (end_v - breakaway) if end_v - breakaway > 0.1 else None
    return breakaway, gain


def analyse_checks(trace: Trace, windows: Windows, loop_delay_ticks: int) -> dict[str, MotorCheck]:
    """Each motor's direction, breakaway and rough gain; a pulse's turn is counted up to
    ``loop_delay_ticks + 10`` ticks after it ends (the wheel runs down, the last ticks come late).
    """
    period_s = trace.period_s
    n = len(trace)
    quantum_rad = encoder_quantum_rad_s(period_s) * period_s  # one count (rad)
    out: dict[str, MotorCheck] = {}
    for m in MOTORS:
        other = "b" if m == "a" else "a"
        pulse = windows[m, "pulse"]
        turn = slice(pulse.start, min(n, pulse.stop + loop_delay_ticks + 10))
        own, cross = (float(np.sum(trace.speed(x)[turn]) * period_s) for x in (m, other))
        moved, moved_other = (abs(x) >= MIN_COUNTS * quantum_rad for x in (own, cross))
        if moved:
            direction = "forward" if own > 0 else "backward"
        else:
            direction = "crossed" if moved_other else "still"
        ramp = windows[m, "ramp"]
        breakaway, gain = _breakaway(trace.speed(m), trace.voltage(m), ramp, loop_delay_ticks)
        out[m] = MotorCheck(m, own, cross, direction, breakaway, gain)
    return out


def verdict(checks: dict[str, MotorCheck]) -> None:
    """Raise :class:`StageError` (one line, what to swap) unless both motors run the right way."""
    for m, c in checks.items():
        other = "b" if m == "a" else "a"
        wrong = {
            "backward": f"motor {m} runs backwards (+{PULSE_V:g} V turned its encoder by "
            f"{c.pulse_turn_rad:+.2f} rad): if wheel {m} turned forwards, swap its encoder "
            f"channels A and B; if it turned backwards, swap motor {m}'s two leads",
            "crossed": f"a pulse on motor {m} moved only encoder {other} ({c.other_turn_rad:+.2f} "
            "rad): the motors' (or the encoders') connections a and b are crossed; swap them",
            "still": f"motor {m} did not turn at +{PULSE_V:g} V (its encoder moved "
            f"{c.pulse_turn_rad:+.3f} rad): check its supply, leads and encoder cable",
        }.get(c.direction)
        if wrong is None and c.breakaway_v is None:
            wrong = (f"motor {m} did not keep turning on a ramp up to {RAMP_MAX_V:g} V: check for "
                     "a blocked wheel or a loose encoder")  # fmt: skip
        if wrong is not None:
            raise StageError(f"checks: {wrong}")


@dataclass(frozen=True)
class Amplitude:
    """The excitation amplitude (V) and the rule that chose it, in words with its numbers."""

    voltage_v: float
    rule: str


def choose_amplitude(checks: dict[str, MotorCheck], step_rad_s: float) -> Amplitude:
    """The square excitation's amplitude (V) from the checks. The report's 10 V, at most the voltage
    at which the faster motor's estimated steady speed is :data:`SPEED_SPAN` × the verification step
    (identify over the speeds the controller will meet, not beyond, where the cart's nonlinearities
    differ) and :data:`FULL_SCALE_FRACTION` of the supply; at least :data:`FRICTION_MARGIN` × the
    larger breakaway voltage, so friction stays small (the floor wins a conflict, within the supply
    bound)."""
    breakaway = max(c.breakaway_v or 0.0 for c in checks.values())
    gains = [c.gain_rad_s_v for c in checks.values() if c.gain_rad_s_v]
    supply_cap = FULL_SCALE_FRACTION * SUPPLY_V
    speed_cap = (breakaway + SPEED_SPAN * step_rad_s / max(gains)) if gains else supply_cap
    ceiling = min(supply_cap, speed_cap)
    floor = min(supply_cap, FRICTION_MARGIN * breakaway)
    voltage = max(floor, min(REPORT_AMPLITUDE_V, ceiling))
    # down to 0.1 V (a number a person can repeat), the ceiling shown as the voltage is cut
    voltage, ceiling = (math.floor(v * 10.0) / 10.0 for v in (voltage, ceiling))
    rule = (
        f"the report's {REPORT_AMPLITUDE_V:g} V, at most {ceiling:.1f} V (the lower of "
        f"{FULL_SCALE_FRACTION:.0%} of the {SUPPLY_V:g} V supply and the voltage whose estimated "
        f"steady speed is {SPEED_SPAN:g} × the {step_rad_s:g} rad/s step: breakaway "
        f"{breakaway:.2f} V + {SPEED_SPAN * step_rad_s:g} rad/s ÷ "
        f"{max(gains) if gains else math.nan:.2f} rad/s/V), at least {floor:.1f} V "
        f"({FRICTION_MARGIN:g} × the larger breakaway voltage)"
    )
    return Amplitude(voltage, rule)


SPLIT = 0.7
NA, NB = 2, 3
MIN_FIT_PERCENT = 80.0
MAX_POLE_RADIUS = 0.99
CROSS_CLEAR_FACTOR = 2.0
TAIL_SIGMAS = 2.0


@dataclass(frozen=True)
class MotorVerdict:
    """One motor's validation figures: simulation fit (%), largest pole radius, cross-correlation
    lags outside the 99 % bound of all lags, the largest over the bound, the whiteness test
    (reported only), and why the model fails (empty: it passes)."""

    validation_fit_percent: float
    pole_radius: float
    cross_outside: int
    cross_lags: int
    cross_ratio: float
    white: bool
    problems: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "passed": not self.problems, "problems": list(self.problems)}


def judge(result: IdentifyResult) -> dict[str, MotorVerdict]:
    """Each motor's verdict (the rules in the module docstring)."""
    out = {}
    for m, r in result.motors.items():
        fit = float(r.chosen.fit_simulation_percent)
        radius = float(r.chosen.model.pole_radius())
        test = r.diagnostics.residuals
        cross, bound = np.abs(test.cross), test.cross_bound_99
        ratio = float(cross.max() / bound) if cross.size and bound > 0.0 else 0.0
        problems = []
        if fit == -math.inf:  # an unstable model's simulation runs away
            problems.append(
                f"validation fit: the simulation diverges (needs >= {MIN_FIT_PERCENT:g} %)"
            )
        elif not fit >= MIN_FIT_PERCENT:
            problems.append(f"validation fit {fit:.1f} % < {MIN_FIT_PERCENT:g} %")
        if not radius < MAX_POLE_RADIUS:
            problems.append(f"a pole at |z| = {radius:.3f} (stable needs < {MAX_POLE_RADIUS:g})")
        if ratio > CROSS_CLEAR_FACTOR:
            problems.append(f"residuals correlated with the input (up to {ratio:.1f} × the 99 % "
                            "bound)")  # fmt: skip
        out[m] = MotorVerdict(
            fit, radius, test.cross_outside, cross.size, ratio, test.white, tuple(problems)
        )
    return out


def _noise_tail(fit: Any) -> bool:
    """The last numerator coefficient within :data:`TAIL_SIGMAS` standard deviations of zero."""
    b_last = float(fit.model.b[-1])
    std = np.asarray(fit.theta_std, dtype=float)
    return fit.model.nb > 1 and bool(np.isfinite(std[-1])) and abs(b_last) < TAIL_SIGMAS * std[-1]


def identify_and_judge(
    trace: Trace, loop_delay_ticks: int
) -> tuple[IdentifyResult, IdentifyRequest, dict[str, MotorVerdict]]:
    """Identify both motors, refit a noise tail with one term fewer, and judge."""
    request = IdentifyRequest(
        motors=MOTORS, na=NA, nb=NB, delay=max(1, int(loop_delay_ticks)), split=SPLIT
    )  # nk: the loop delay, at least 1
    result = identify([trace], request)
    short = tuple(m for m, r in result.motors.items() if _noise_tail(r.chosen))
    if short:
        again = identify([trace], replace(request, nb=NB - 1, motors=short))
        motors = {m: again.motors.get(m, r) for m, r in result.motors.items()}
        note = f"motor(s) {', '.join(short)}: nb = {NB - 1}, the last term being noise"
        result = IdentifyResult(result.period_s, motors, (*result.notes, note))
    return result, request, judge(result)


def model_failure(verdicts: dict[str, MotorVerdict], excitation_v: float) -> StageError | None:
    """The :class:`StageError` naming the first failing motor and why (one line), or None."""
    for m, v in verdicts.items():
        if v.problems:
            return StageError(
                f"identification: motor {m}'s model fails validation ({'; '.join(v.problems)}); "
                f"the {excitation_v:g} V excitation does not give a model to tune on: check the "
                "encoder (noise, loose cable) and that nothing touches the wheels"
            )
    return None


STEP_RAD_S = 10.0
REFERENCE = f"step:{STEP_RAD_S:g}"
DURATION_S = 2.0
TARGET_OVERSHOOT_PERCENT = 5.0
TARGET_SETTLING_S = 0.15
TRUE_SPEED_TOLERANCE_PP = 1.0  # percentage points: the loop's own tick-to-tick spread


def run_argv(plant: str, controller: Path, out: Path, *, fast: bool,
             plant_options: Sequence[str] = ()) -> list[str]:  # fmt: skip
    """The ``cartctl run`` arguments of the verification step."""
    options = {
        "--plant": plant,
        "--controller": str(controller),
        "--reference": REFERENCE,
        "--duration": f"{DURATION_S:g}",
        "--rerun": "save",
        "--out": str(out),
        "--name": "verification",
    }
    argv = ["run", *(arg for pair in options.items() for arg in pair), "--json", *plant_options]
    return argv + (["--fast"] if fast else [])


@dataclass(frozen=True)
class Verification:
    """Measured (worse of motors a and b; None: did not settle) against predicted (the tuning's
    ``nominal_…`` and ``worst_…`` figures), the pass ``limits`` with the ``speed`` judged, and the
    verdict."""

    measured: dict[str, float | None]
    predicted: dict[str, float | None]
    limits: dict[str, Any]
    passed: bool

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["pass"] = out.pop("passed")
        return out


def compare(summary: dict[str, Any], predicted: dict[str, float | None],
            smoothed: dict[str, dict[str, Any]] | None = None) -> Verification:  # fmt: skip
    """Judge a ``cartctl run --json`` summary against the tuning's prediction (module docstring);
    ``smoothed`` per motor, the run's figures on the smoothed speed, judged where there is no true
    speed."""
    motors = summary.get("motors") or {}
    count_pp = 100.0 * encoder_quantum_rad_s() / STEP_RAD_S
    if summary.get("metrics_signal") == "true_speed":
        speed, tol = "true", TRUE_SPEED_TOLERANCE_PP
    elif smoothed:
        speed, tol = "smoothed", TRUE_SPEED_TOLERANCE_PP + 0.5 * count_pp
        motors = smoothed
    else:
        speed, tol = "encoder", count_pp
    worst = worst_metrics(motors)
    measured = {k: worst[k] for k in ("overshoot_percent", "settling_time_s")}
    max_os = max(TARGET_OVERSHOOT_PERCENT, predicted.get("nominal_overshoot_percent") or 0.0) + tol
    max_ts = max(TARGET_SETTLING_S, (predicted.get("nominal_settling_time_s") or 0.0) + 0.02)
    limits = {"overshoot_percent": max_os, "settling_time_s": max_ts, "speed": speed}
    os_, ts = measured["overshoot_percent"], measured["settling_time_s"]
    passed = os_ is not None and ts is not None and os_ <= max_os and ts <= max_ts
    return Verification(measured, dict(predicted), limits, bool(passed))
