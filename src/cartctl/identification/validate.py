"""Model validation: simulate a model on a recorded input and compare with the measured speed.

The last check of the identification stage (report §3.3, figures 6 and 7) and the work of
``cartctl validate``: the model runs from rest on the trace's commanded voltage (simulation, not
one-step prediction), and the result says how well it follows the measured speed: the fit (%), the
absolute error over time, and, when the input is a single step, the step metrics of the measured
and simulated responses side by side. Pure numpy on a :class:`~cartctl.data.trace.Trace`; no I/O.
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

__all__ = [
    "PERIOD_TOLERANCE",
    "ModelValidation",
    "StepComparison",
    "ValidationResult",
    "check_period",
    "validate",
    "validate_models",
]

PERIOD_TOLERANCE = 0.1
"""How far (as a fraction) a trace's median time step may differ from the model's Ts."""


def _where(trace: Trace) -> str:
    return trace.source if trace.source else "the trace"


def check_period(trace: Trace, period_s: float) -> None:
    """Refuse a trace whose tick differs from the model's sample period.

    Raises
    ------
    InputError
        The median time step of ``trace`` differs from ``period_s`` (s) by more than
        :data:`PERIOD_TOLERANCE`, or the trace has fewer than two ticks.
    """
    step_s = trace.period_s
    if abs(step_s - period_s) > PERIOD_TOLERANCE * period_s:
        raise InputError(
            f"{_where(trace)} is sampled every {step_s * 1e3:.4g} ms but the model has "
            f"Ts = {period_s * 1e3:.4g} ms; record the trace at the model's period"
        )


@dataclass(frozen=True)
class StepComparison:
    """Step metrics of the measured and the simulated response to one step of the input.

    Attributes
    ----------
    amplitude_v : float
        The input step (V).
    onset_s : float
        When the step is commanded, on the trace's time axis (s).
    measured, simulated : StepInfo
        Metrics of each response (speeds in rad/s), from the onset, starting at 0 rad/s.
    """

    amplitude_v: float
    onset_s: float
    measured: StepInfo
    simulated: StepInfo

    @property
    def steady_state_error_rad_s(self) -> float:
        """The model's steady-state error: measured − simulated final value (rad/s)."""
        return self.measured.steady_state_value - self.simulated.steady_state_value

    def to_dict(self) -> dict[str, Any]:
        """JSON form: amplitude, onset, both metric sets and the steady-state error."""
        return {
            "amplitude_v": self.amplitude_v,
            "onset_s": self.onset_s,
            "measured": self.measured.to_dict(),
            "simulated": self.simulated.to_dict(),
            "steady_state_error": self.steady_state_error_rad_s,
        }


@dataclass(frozen=True, eq=False)
class ValidationResult:
    """A model simulated on one motor's recorded input, against the measured speed.

    Attributes
    ----------
    motor : str
        'a' or 'b'.
    fit_simulation_percent : float
        Normalised-RMSE fit of the simulation (%, 100 is perfect); NaN for a constant speed.
    time_s : ndarray, shape (n,)
        The trace's time (s).
    voltage_v : ndarray, shape (n,)
        The input the model was driven with (V).
    measured_rad_s, simulated_rad_s : ndarray, shape (n,)
        Measured and simulated speed (rad/s).
    abs_error_rad_s : ndarray, shape (n,)
        |measured − simulated| (rad/s).
    step : StepComparison or None
        Present when the input is a single step from 0 V.
    unstable_pole : float or None
        |z| of the model's largest pole when it is unstable (then the simulation runs away and
        there is no fit: NaN, and no step comparison), else None.
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
        """JSON form: the fit, the error summary and the step comparison (or None); no arrays."""
        return {
            "fit_simulation_percent": finite_or_none(self.fit_simulation_percent),
            "abs_error": self.error_summary(),
            "step": None if self.step is None else self.step.to_dict(),
            "stable": self.unstable_pole is None,
        }


def validate(model: ArxModel, trace: Trace, motor: str) -> ValidationResult:
    """Simulate ``model`` from rest on motor ``motor``'s input and compare with its measured speed.

    Parameters
    ----------
    model : ArxModel
        The motor's model (V in, rad/s out).
    trace : Trace
        A recorded experiment at the model's sample period.
    motor : {'a', 'b'}
        Whose voltage drives the model and whose speed it is compared with.

    Returns
    -------
    ValidationResult

    Raises
    ------
    InputError
        An unknown motor, a trace at another sample period, or a motor whose voltage is zero
        throughout (nothing to validate).
    """
    voltage = trace.voltage(motor)
    measured = trace.speed(motor)
    check_period(trace, model.period_s)
    if not np.any(voltage):
        others = [m for m in MOTORS if m != motor and np.any(trace.voltage(m))]
        hint = f"choose --motor {others[0]}" if others else "the trace drives neither motor"
        raise InputError(
            f"motor {motor}'s voltage is zero throughout {_where(trace)}; nothing to validate "
            f"— {hint}"
        )
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable model may overflow
        simulated = model.simulate(voltage)
    if not model.is_stable():
        pole = model.pole_radius()
        runaway = np.where(np.isfinite(simulated), simulated, np.nan)
        return ValidationResult(
            motor=motor, fit_simulation_percent=math.nan, time_s=trace.time_s,
            voltage_v=voltage, measured_rad_s=measured, simulated_rad_s=runaway,
            abs_error_rad_s=np.abs(measured - runaway), unstable_pole=pole,
        )  # fmt: skip
    abs_error = np.abs(measured - simulated)
    return ValidationResult(
        motor=motor,
        fit_simulation_percent=fit_percent(measured, simulated),
        time_s=trace.time_s,
        voltage_v=voltage,
        measured_rad_s=measured,
        simulated_rad_s=simulated,
        abs_error_rad_s=abs_error,
        step=_compare_step(trace.time_s, voltage, measured, simulated),
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
    """The models of a model file validated on one trace, per motor.

    Attributes
    ----------
    period_s : float
        The models' sample period Ts (s).
    data : str or None
        The trace's source file.
    model : str or None
        The model file.
    results : dict of str to ValidationResult
        Per validated motor, in motor order.
    skipped : tuple of str
        Motors passed over because their voltage is zero throughout the trace.
    """

    period_s: float
    data: str | None
    model: str | None
    results: dict[str, ValidationResult]
    skipped: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The ``validate --json`` object: Ts, data, model, motors (and skipped motors)."""
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

    Parameters
    ----------
    model_file : ModelFile
        The models; each motor in ``motors`` needs one.
    trace : Trace
        The recorded experiment.
    motors : sequence of {'a', 'b'}
        The motors to validate, e.g. ``("a", "b")``.
    skip_idle : bool
        Pass over (and list in ``skipped``) a motor whose voltage is zero throughout, instead of
        raising. At least one motor must remain.

    Returns
    -------
    ModelValidation

    Raises
    ------
    InputError
        A motor without a model, a trace at another sample period, a motor with zero voltage
        throughout (unless skipped), or every motor skipped.
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
