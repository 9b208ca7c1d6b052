"""Model validation (report §3.3, figures 6 and 7; ``cartctl validate``): the model runs from
rest on a trace's commanded voltage (a simulation, not a one-step prediction) and is compared with
the measured speed: the fit (%), the absolute error over time and, for a single step input, the
step metrics of both responses side by side.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cartctl.data.modelfile import ModelFile
from cartctl.data.trace import MOTORS, Trace
from cartctl.errors import InputError
from cartctl.measures.metrics import finite_or_none, fit_percent
from cartctl.measures.stepinfo import StepInfo, find_step, step_info
from cartctl.model import ArxModel

PERIOD_TOLERANCE = 0.1
"""How far (as a fraction) a trace's median time step may differ from the model's Ts."""


def _where(trace: Trace) -> str:
    return trace.source if trace.source else "the trace"


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
        return {
            "amplitude_v": self.amplitude_v,
            "onset_s": self.onset_s,
            "measured": self.measured.to_dict(),
            "simulated": self.simulated.to_dict(),
            "steady_state_error": self.steady_state_error_rad_s,
        }


@dataclass(frozen=True, eq=False)
class ValidationResult:
    """A model simulated on one motor's recorded input against the measured speed (rad/s, V, s).

    ``fit_simulation_percent`` is the NRMSE fit (NaN for a constant speed); ``step`` is present
    for a single step from 0 V; ``unstable_pole`` is |z| of the largest pole of an unstable
    model, whose simulation runs away (no fit, no step comparison).
    """

    motor: str
    fit_simulation_percent: float
    time_s: np.ndarray = field(repr=False)
    voltage_v: np.ndarray = field(repr=False)
    measured_rad_s: np.ndarray = field(repr=False)
    simulated_rad_s: np.ndarray = field(repr=False)
    abs_error_rad_s: np.ndarray = field(repr=False)
    step: StepComparison | None = None
    unstable_pole: float | None = None

    def error_summary(self) -> dict[str, float]:
        """Max, mean and RMS of the absolute error (rad/s)."""
        e = self.abs_error_rad_s
        if self.unstable_pole is not None:
            return {"max": math.nan, "mean": math.nan, "rms": math.nan}
        return {
            "max": float(np.max(e)),
            "mean": float(np.mean(e)),
            "rms": float(np.sqrt(np.mean(e**2))),
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "fit_simulation_percent": finite_or_none(self.fit_simulation_percent),
            "abs_error": self.error_summary(),
            "step": None if self.step is None else self.step.to_dict(),
            "stable": self.unstable_pole is None,
        }


def validate(model: ArxModel, trace: Trace, motor: str) -> ValidationResult:
    """Simulate ``model`` from rest on motor ``motor``'s input and compare with its measured speed.

    Refuses a trace whose tick differs from the model's Ts by more than
    :data:`PERIOD_TOLERANCE`, and a motor whose voltage is zero throughout.
    """
    voltage = trace.voltage(motor)
    measured = trace.speed(motor)
    step_s, period_s = trace.period_s, model.period_s
    if abs(step_s - period_s) > PERIOD_TOLERANCE * period_s:
        raise InputError(
            f"{_where(trace)} is sampled every {step_s * 1e3:.4g} ms but the model has "
            f"Ts = {period_s * 1e3:.4g} ms; record the trace at the model's period"
        )
    if not np.any(voltage):
        others = [m for m in MOTORS if m != motor and np.any(trace.voltage(m))]
        hint = f"choose --motor {others[0]}" if others else "the trace drives neither motor"
        raise InputError(
            f"motor {motor}'s voltage is zero throughout {_where(trace)}; nothing to validate "
            f"— {hint}"
        )
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable model may overflow
        simulated = model.simulate(voltage)
    stable = model.is_stable()
    if not stable:
        simulated = np.where(np.isfinite(simulated), simulated, np.nan)
    return ValidationResult(
        motor=motor,
        fit_simulation_percent=fit_percent(measured, simulated) if stable else math.nan,
        time_s=trace.time_s,
        voltage_v=voltage,
        measured_rad_s=measured,
        simulated_rad_s=simulated,
        abs_error_rad_s=np.abs(measured - simulated),
        step=_compare_step(trace.time_s, voltage, measured, simulated) if stable else None,
        unstable_pole=None if stable else model.pole_radius(),
    )


def _compare_step(
    time_s: np.ndarray, voltage: np.ndarray, measured: np.ndarray, simulated: np.ndarray
) -> StepComparison | None:
    """Step metrics of both responses, when the input is one step from 0 V with samples after it."""
    onset = find_step(voltage)
    if onset is None or onset.index > len(time_s) - 2:
        return None
    onset_s = float(time_s[onset.index])
    try:
        measured_info = step_info(time_s, measured, onset_s=onset_s)
        simulated_info = step_info(time_s, simulated, onset_s=onset_s)
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
        return {
            "Ts": self.period_s,
            "data": self.data,
            "model": self.model,
            "motors": {name: r.to_dict() for name, r in self.results.items()},
            "skipped": list(self.skipped),
        }


def validate_models(
    model_file: ModelFile, trace: Trace, motors: Sequence[str], *, skip_idle: bool = False
) -> ModelValidation:
    """Validate each named motor's model on ``trace``.

    With ``skip_idle``, a motor whose voltage is zero throughout is passed over instead of
    refused; at least one must remain.
    """
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
            f"the voltage of motor(s) {', '.join(skipped)} is zero throughout {_where(trace)}; "
            "nothing to validate"
        )
    path = None if model_file.path is None else str(model_file.path)
    return ModelValidation(model_file.period_s, trace.source, path, results, tuple(skipped))
