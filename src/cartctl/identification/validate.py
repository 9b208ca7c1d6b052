"""Models and motors against measured traces (report §3.3). ``cartctl validate`` (figures 6, 7):
the model simulated from rest on a trace's voltage against the measured speed (fit, absolute
error, and both step responses' metrics for a single step). ``cartctl linearity`` (equation 11,
figure 8): whether the responses to two steps add up to the response to their sum (Coulomb
friction makes the sum run above: each small step loses the friction once, the sum only once).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cartctl.cart import encoder_quantum_rad_s
from cartctl.data.modelfile import ModelFile
from cartctl.data.trace import MOTORS, Trace
from cartctl.errors import InputError
from cartctl.identification.arx import simulation_fit
from cartctl.measures.metrics import finite_or_none
from cartctl.measures.stepinfo import StepInfo, StepOnset, final_value, find_step, step_info
from cartctl.model import ArxModel

PERIOD_TOLERANCE = 0.1
"""How far (as a fraction) a trace's median time step may differ from the model's Ts."""


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


@dataclass(frozen=True)
class StepComparison:
    """Step metrics (speeds in rad/s, from the onset at ``onset_s`` s, starting at 0 rad/s) of the
    measured and the simulated response to one input step of ``amplitude_v`` V."""

    amplitude_v: float
    onset_s: float
    measured: StepInfo
    simulated: StepInfo

    @property
    def steady_state_error_rad_s(self) -> float:
        """The model's steady-state error: measured − simulated final value (rad/s)."""
        return self.measured.steady_state_value - self.simulated.steady_state_value

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"amplitude_v": self.amplitude_v, "onset_s": self.onset_s}
        out |= {"measured": self.measured.to_dict(), "simulated": self.simulated.to_dict()}
        return out | {"steady_state_error": self.steady_state_error_rad_s}


@dataclass(frozen=True, eq=False)
class ValidationResult:
    """A model simulated on one motor's recorded input against the measured speed (rad/s, V, s):
    the NRMSE fit of :func:`~cartctl.identification.arx.simulation_fit` (NaN for a constant speed,
    −inf for an unstable model), the step comparison for a single step from 0 V, and
    ``unstable_pole`` |z| of a model that is not stable, whose simulation runs away or drifts (no
    fit, no step), with its ``stability`` (:meth:`~cartctl.model.ArxModel.stability`)."""

    motor: str
    fit_simulation_percent: float
    time_s: np.ndarray = field(repr=False)
    voltage_v: np.ndarray = field(repr=False)
    measured_rad_s: np.ndarray = field(repr=False)
    simulated_rad_s: np.ndarray = field(repr=False)
    abs_error_rad_s: np.ndarray = field(repr=False)
    step: StepComparison | None = None
    unstable_pole: float | None = None
    stability: str = "stable"

    def error_summary(self) -> dict[str, float]:
        """Max, mean and RMS of the absolute error (rad/s)."""
        e = np.full(1, math.nan) if self.unstable_pole is not None else self.abs_error_rad_s
        return {"max": float(np.max(e)), "mean": float(np.mean(e)), "rms": _rms(e)}

    def to_dict(self) -> dict[str, Any]:
        return {
            "fit_simulation_percent": finite_or_none(self.fit_simulation_percent),
            "abs_error": self.error_summary(),
            "step": None if self.step is None else self.step.to_dict(),
            "stable": self.unstable_pole is None,
        }


def validate(model: ArxModel, trace: Trace, motor: str) -> ValidationResult:
    """Simulate ``model`` from rest on ``motor``'s voltage and compare with its measured speed;
    refuses a trace off the model's Ts by :data:`PERIOD_TOLERANCE` and a motor never driven."""
    voltage, measured = trace.voltage(motor), trace.speed(motor)
    where = trace.source or "the trace"
    step_s, period_s = trace.period_s, model.period_s
    if abs(step_s - period_s) > PERIOD_TOLERANCE * period_s:
        raise InputError(
            f"{where} is sampled every {step_s * 1e3:.4g} ms but the model has "
            f"Ts = {period_s * 1e3:.4g} ms; record the trace at the model's period"
        )
    if not np.any(voltage):
        others = [m for m in MOTORS if m != motor and np.any(trace.voltage(m))]
        hint = f"choose --motor {others[0]}" if others else "the trace drives neither motor"
        raise InputError(
            f"motor {motor}'s voltage is zero throughout {where}; nothing to validate — {hint}"
        )
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable model may overflow
        simulated = model.simulate(voltage)
    stable = model.is_stable()
    if not stable:
        simulated = np.where(np.isfinite(simulated), simulated, np.nan)
    step = _compare_step(trace.time_s, voltage, measured, simulated, period_s) if stable else None
    return ValidationResult(
        motor=motor,
        fit_simulation_percent=(  # NaN, not simulation_fit's refusal, for a non-finite trace
            simulation_fit(model, [(measured, voltage)])
            if np.isfinite(measured).all() and np.isfinite(voltage).all()
            else math.nan
        ),
        time_s=trace.time_s,
        voltage_v=voltage,
        measured_rad_s=measured,
        simulated_rad_s=simulated,
        abs_error_rad_s=np.abs(measured - simulated),
        step=step,
        unstable_pole=None if stable else model.pole_radius(),
        stability=model.stability(),
    )


def _compare_step(
    time_s: np.ndarray,
    voltage: np.ndarray,
    measured: np.ndarray,
    simulated: np.ndarray,
    period_s: float,
) -> StepComparison | None:
    """Step metrics of both responses, when the input is one step from 0 V with samples after it;
    settling in run's and review's band, max(2 % of the step, one encoder count per tick)."""
    onset = find_step(voltage)
    if onset is None or onset.index > len(time_s) - 2:
        return None
    onset_s, floor = float(time_s[onset.index]), encoder_quantum_rad_s(period_s)
    try:
        measured_info = step_info(time_s, measured, onset_s=onset_s, settling_floor=floor)
        simulated_info = step_info(time_s, simulated, onset_s=onset_s, settling_floor=floor)
    except InputError:  # a response that ends where it starts has no step metrics
        return None
    return StepComparison(onset.amplitude, onset_s, measured_info, simulated_info)


@dataclass(frozen=True, eq=False)
class ModelValidation:
    """The models of a model file (Ts ``period_s``) validated on one trace, per motor; motors
    passed over for a voltage zero throughout in ``skipped``."""

    period_s: float
    data: str | None
    model: str | None
    results: dict[str, ValidationResult]
    skipped: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        motors = {name: r.to_dict() for name, r in self.results.items()}
        out = {"Ts": self.period_s, "data": self.data, "model": self.model, "motors": motors}
        return out | {"skipped": list(self.skipped)}


def validate_models(
    model_file: ModelFile, trace: Trace, motors: Sequence[str], *, skip_idle: bool = False
) -> ModelValidation:
    """Validate each named motor's model on ``trace``; with ``skip_idle`` a motor never driven is
    passed over instead of refused, but one must remain."""
    if not motors:
        raise InputError("no motor to validate; name 'a', 'b' or both")
    results: dict[str, ValidationResult] = {}
    skipped: list[str] = []
    for name in motors:
        model = model_file.motor(name)
        if skip_idle and not np.any(trace.voltage(name)):
            skipped.append(name)
            continue
        results[name] = validate(model, trace, name)
    if not results:
        raise InputError(
            f"the voltage of motor(s) {', '.join(skipped)} is zero throughout {trace.source or 'the trace'}; "
            "nothing to validate"
        )
    path = None if model_file.path is None else str(model_file.path)
    return ModelValidation(model_file.period_s, trace.source, path, results, tuple(skipped))


AMPLITUDE_REL_TOLERANCE = 0.02
"""Small + large may differ from the summed step by this fraction of the summed step ..."""

AMPLITUDE_ABS_TOLERANCE_V = 0.1  # ... or by this many volts, whichever is larger

_ROLES = ("small", "large", "sum")
_MIN_ALIGNED_TICKS = 2


@dataclass(frozen=True, eq=False)
class LinearityResult:
    """The superposition test on one motor: the small, large and sum traces' files, voltage steps
    (V) and onsets (s, each on its own trace's axis); over the span all three cover after their
    onsets, the aligned speeds (rad/s), their sum ``speed_added_rad_s`` = small + large, and
    ``error_rad_s`` = sum − added (positive where the summed step runs faster)."""

    motor: str
    period_s: float
    sources: tuple[str | None, str | None, str | None]
    amplitudes_v: tuple[float, float, float]
    onsets_s: tuple[float, float, float]
    time_s: np.ndarray = field(repr=False)
    speed_small_rad_s: np.ndarray = field(repr=False)
    speed_large_rad_s: np.ndarray = field(repr=False)
    speed_sum_rad_s: np.ndarray = field(repr=False)
    speed_added_rad_s: np.ndarray = field(repr=False)
    error_rad_s: np.ndarray = field(repr=False)

    @property
    def mean_error_rad_s(self) -> float:
        return float(np.mean(self.error_rad_s))

    @property
    def max_abs_error_rad_s(self) -> float:
        return float(np.max(np.abs(self.error_rad_s)))

    @property
    def rms_error_rad_s(self) -> float:
        return _rms(self.error_rad_s)

    @property
    def steady_state_sum_rad_s(self) -> float:
        """Final value of the summed step's response: mean of its last 5 % (rad/s)."""
        return final_value(self.speed_sum_rad_s)

    @property
    def rms_error_percent(self) -> float | None:
        """RMS error over the RMS of the summed step's response (%); None if that is zero."""
        rms_sum = _rms(self.speed_sum_rad_s)
        return 100.0 * self.rms_error_rad_s / rms_sum if rms_sum > 0.0 else None

    @property
    def mean_error_percent(self) -> float | None:
        """Mean error over the summed step's steady state (%); None if that is zero."""
        steady = self.steady_state_sum_rad_s
        return 100.0 * self.mean_error_rad_s / steady if steady != 0.0 else None

    def to_dict(self) -> dict[str, Any]:
        return {
            "motor": self.motor,
            "Ts": self.period_s,
            "data": dict(zip(_ROLES, self.sources, strict=True)),
            "amplitudes_v": dict(zip(_ROLES, self.amplitudes_v, strict=True)),
            "onsets_s": dict(zip(_ROLES, self.onsets_s, strict=True)),
            "duration_s": float(self.time_s[-1]),
            "steady_state_sum_rad_s": self.steady_state_sum_rad_s,
            "error_rad_s": {
                "mean": self.mean_error_rad_s,
                "max_abs": self.max_abs_error_rad_s,
                "rms": self.rms_error_rad_s,
            },
            "relative_percent": {"rms": self.rms_error_percent, "mean": self.mean_error_percent},
        }


def _onset(trace: Trace, motor: str, role: str) -> StepOnset:
    voltage = trace.voltage(motor)
    onset = find_step(voltage)
    where = trace.source or f"the {role} step trace"
    if onset is None:
        held = "zero throughout" if not np.any(voltage) else "not a single step from 0 V"
        raise InputError(
            f"motor {motor}'s voltage in {where} is {held} "
            f"(from {np.min(voltage):g} V to {np.max(voltage):g} V); the superposition test "
            "needs three step experiments on that motor"
        )
    if len(trace) - onset.index < _MIN_ALIGNED_TICKS:
        raise InputError(
            f"{where} ends {len(trace) - onset.index} tick(s) after its step; "
            "record the response to the step"
        )
    return onset


def linearity(small: Trace, large: Trace, total: Trace, motor: str = "a") -> LinearityResult:
    """The superposition test of ``motor``'s responses to steps from 0 V of ``small``, ``large``
    and their sum ``total``; refuses a trace that is not one such step, traces with different
    ticks and amplitudes that do not add up (beyond 2 % or 0.1 V)."""
    traces = (small, large, total)
    onsets = tuple(_onset(t, motor, role) for t, role in zip(traces, _ROLES, strict=True))
    periods = [t.period_s for t in traces]
    if max(periods) - min(periods) > 0.01 * min(periods):
        listing = ", ".join(f"{p * 1e3:.4g} ms" for p in periods)
        raise InputError(f"the three traces must share one tick; their time steps are {listing}")
    amp_small, amp_large, amp_sum = (o.amplitude for o in onsets)
    tolerance = max(AMPLITUDE_REL_TOLERANCE * abs(amp_sum), AMPLITUDE_ABS_TOLERANCE_V)
    if abs(amp_small + amp_large - amp_sum) > tolerance:
        raise InputError(
            f"the steps do not add up: {amp_small:g} V + {amp_large:g} V = "
            f"{amp_small + amp_large:g} V, but the sum step is {amp_sum:g} V (tolerance "
            f"{tolerance:.3g} V); give the small, the large and their sum, in that order"
        )
    pairs = list(zip(traces, onsets, strict=True))
    n = min(len(t) - o.index for t, o in pairs)
    speeds = [t.speed(motor)[o.index : o.index + n] for t, o in pairs]
    added = speeds[0] + speeds[1]
    period_s = float(f"{np.median(periods):.9g}")  # 0.01, not 0.010000000000000009
    on_small, on_large, on_sum = (float(t.time_s[o.index]) for t, o in pairs)
    return LinearityResult(
        motor=motor,
        period_s=period_s,
        sources=(small.source, large.source, total.source),
        amplitudes_v=(amp_small, amp_large, amp_sum),
        onsets_s=(on_small, on_large, on_sum),
        time_s=np.arange(n) * period_s,
        speed_small_rad_s=speeds[0],
        speed_large_rad_s=speeds[1],
        speed_sum_rad_s=speeds[2],
        speed_added_rad_s=added,
        error_rad_s=speeds[2] - added,
    )
