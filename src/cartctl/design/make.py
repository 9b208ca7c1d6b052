"""Designs from a request: the controller of each motor, its analysis, and its controller file.

One path for ``cartctl design``, ``cartctl tune`` and the Python API: :func:`design_motor` makes
one motor's runtime controller with its JSON and file entries; :func:`design_models` adds the
simulated step against the time-optimal bound for every motor asked for; :func:`controller_file`
makes the file to save.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from cartctl.cart import nk_fits_loop_delay
from cartctl.data.modelfile import ModelFile
from cartctl.design.analysis import StepAnalysis, simulate_step
from cartctl.design.build import make_estimator, pi_entry, poles_entry
from cartctl.design.controller_ss import feedback_tf_coeffs
from cartctl.design.controllerfile import ControllerFile, common_loop_delay, file_sha256
from cartctl.design.kalman import design_kalman
from cartctl.design.limit import in_settling_band, settling_bound
from cartctl.design.loop import loop_analysis
from cartctl.design.pi import design_pi, design_pi_bandwidth
from cartctl.design.poles import design_poles
from cartctl.design.request import DesignRequest, check_loop_delay
from cartctl.errors import InputError
from cartctl.model import ArxModel
from cartctl.runtime.base import Controller
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController

ANALYSIS_KEYS = (
    "phase_margin_deg", "gain_margin_db", "crossover_hz", "sensitivity_peak", "closed_loop_poles",
    "estimator_poles", "step", "settling_bound_s", "settling_ratio",
    "settling_bound_loop_delay_ticks",
)  # fmt: skip
"""The entries of a motor's design that its controller file keeps under ``analysis``."""


@dataclass(frozen=True)
class MotorDesign:
    """One motor's design.

    Attributes
    ----------
    controller : Controller
        The runtime controller, as ``cartctl run`` builds it from the file.
    entry : dict
        The design's figures (gains, margins, poles; the ``design --json`` entry).
    file_entry : dict
        The ``[motors.X]`` table of the controller file (without ``analysis``).
    """

    controller: Controller
    entry: dict[str, Any]
    file_entry: dict[str, Any]


def design_motor(request: DesignRequest, model: ArxModel) -> MotorDesign:
    """Design one motor's controller as ``request`` asks."""
    extra = request.extra_delay_ticks
    if request.method == "pi":
        if request.bandwidth_hz is not None:
            d = design_pi_bandwidth(model, bandwidth_hz=request.bandwidth_hz,
                                    phase_margin_deg=request.phase_margin_deg,
                                    extra_delay_ticks=extra)  # fmt: skip
        else:
            d = design_pi(model, phase_margin_deg=request.phase_margin_deg,
                          crossover_hz=request.crossover_hz, extra_delay_ticks=extra)  # fmt: skip
        kalman = None
        if request.estimator == "kalman":
            kalman = design_kalman(model, process_noise_std_v=request.process_noise_std_v,
                                   bias_drift_std_v=request.bias_drift_std_v,
                                   extra_noise_std_rad_s=request.extra_noise_std_rad_s,
                                   extra_delay_ticks=extra,
                                   timing_noise_std_ticks=request.timing_noise_std_ticks)  # fmt: skip
        ctrl = PiController(d.kp, d.ki, model.period_s, voltage_limit_v=request.voltage_limit_v,
                            anti_windup=request.anti_windup,
                            estimator=None if kalman is None else make_estimator(kalman))  # fmt: skip
        entry = {**d.to_dict(), **d.analysis()}
        if kalman is not None:
            entry["estimator_poles"] = [[p.real, p.imag] for p in kalman.poles()]
        return MotorDesign(ctrl, entry, pi_entry(d, request.anti_windup, kalman))
    poles = request.pole_list()
    placement = design_poles(
        model,
        poles=poles,
        settling_time_s=None if poles else request.settling_time_s,
        overshoot_percent=None if poles else request.overshoot_percent,
        extra_delay_ticks=extra,
        process_noise_std_v=request.process_noise_std_v,
        bias_drift_std_v=request.bias_drift_std_v,
        extra_noise_std_rad_s=request.extra_noise_std_rad_s,
        timing_noise_std_ticks=request.timing_noise_std_ticks,
    )
    feedback = StateFeedbackController(
        placement,
        estimator=make_estimator(placement.estimator),
        voltage_limit_v=request.voltage_limit_v,
    )
    num, den = feedback_tf_coeffs(placement)
    loop = loop_analysis(num, den, model, extra)
    entry = {
        **{k: v for k, v in placement.to_dict().items() if k != "estimator"},
        "phase_margin_deg": loop["phase_margin_deg"],
        "gain_margin_db": loop["gain_margin_db"],
        "crossover_hz": loop["crossover_hz"],
        "sensitivity_peak": loop["sensitivity_peak"],
        "sensitivity_peak_db": loop["sensitivity_peak_db"],
        "controller_num": num.tolist(),
        "controller_den": den.tolist(),
    }
    return MotorDesign(feedback, entry, poles_entry(placement, num, den))


def nk_note(nk: Mapping[str, int], loop_delay_ticks: int) -> str | None:
    """One line on models whose input delay is not the loop delay + 1 (the report's timing), or
    None when every motor's is. ``loop_delay_ticks`` is the loop the data was recorded in."""
    odd = sorted({n for n in nk.values() if n != loop_delay_ticks + 1})
    if not odd:
        return None
    n = odd[0]
    if n == loop_delay_ticks:
        return (
            f"nk = {n} with loop delay {loop_delay_ticks}: the command lands within the tick, so "
            "the next measurement already sees part of it; the model's first input term covers "
            f"that, and the design is for loop delay {loop_delay_ticks}"
        )
    if n > loop_delay_ticks + 1:
        return (
            f"nk = {n} with loop delay {loop_delay_ticks}: the motor answers {n - 1 - loop_delay_ticks}"
            " tick(s) later than the loop alone explains (a slow start, a dead zone or a given "
            "--delay); the model carries that lag"
        )
    return (
        f"nk = {n} with loop delay {loop_delay_ticks}: the model answers sooner than the loop "
        "lets a command land; the recorded loop delay or the identified delay is wrong"
    )


def loop_delay_for(
    request: DesignRequest,
    models: Mapping[str, ArxModel],
    recorded: int | None = None,
    *,
    strict: bool = True,
) -> tuple[int | None, str | None]:
    """The loop delay a design is for, and a line explaining it where nk and it disagree.

    In order: ``request.loop_delay_ticks`` (``--loop-delay``) if it fits every model
    (:func:`~cartctl.design.request.check_loop_delay`, InputError otherwise); the loop delay the
    models' data was recorded in (``recorded``, the model file's ``loop_delay_ticks``) plus the
    extra delay, when every model's nk is that loop delay or one more (the checks of
    ``--loop-delay``); else the models' common nk − 1 + extra delay, as for a model file without
    a loop delay. Motors whose nk differ then give None, or with ``strict`` an InputError: a
    controller file is for one loop.
    """
    extra = request.extra_delay_ticks
    nks = {m: mod.nk for m, mod in models.items()}
    if request.loop_delay_ticks is not None:
        for model in models.values():
            check_loop_delay(request.loop_delay_ticks, model.nk, extra)
        return request.loop_delay_ticks, nk_note(nks, request.loop_delay_ticks - extra)
    note = None
    if recorded is not None:
        if all(nk_fits_loop_delay(n, recorded) for n in nks.values()):
            return recorded + extra, nk_note(nks, recorded)
        shown = ", ".join(f"nk = {n}" for n in sorted(set(nks.values())))
        note = (
            f"the model's {shown} does not fit the loop delay {recorded} it was recorded in "
            f"(nk = {recorded} or {recorded + 1} would): designing for nk - 1 + extra delay, as "
            "for a model without a loop delay; --loop-delay N states another"
        )
    try:
        return common_loop_delay(nks, extra), note
    except ValueError as exc:
        if strict:
            raise InputError(str(exc)) from None
        return None, note


def check_models(
    models: ModelFile | Mapping[str, ArxModel], motors: tuple[str, ...], name: str | None = None
) -> None:
    """Refuse models no design can use, before any design work (one line naming the file).

    Every motor's model must be stable: a PI needs it, and the simulated step and the settling
    bound of every design run on it. ``cartctl design`` and ``cartctl tune`` refuse with this line,
    naming the file as ``name`` (as the user gave it; default the model file's path).

    Raises
    ------
    InputError
        A motor's model has a pole on or outside the unit circle.
    """
    if name is None and isinstance(models, ModelFile) and models.path:
        name = str(models.path)
    where = f"{name}: " if name else ""
    for m in motors:
        model = models.motor(m) if isinstance(models, ModelFile) else models[m]
        if not model.is_stable():
            raise InputError(
                f"{where}motor {m}'s model is unstable (pole at |z| = {model.pole_radius():.4g}); "
                "a design needs a stable model (its simulated step and settling bound run on "
                "it): identify it again"
            )


@dataclass(frozen=True)
class Designs:
    """The designs of the motors asked for, each with its simulated step.

    Attributes
    ----------
    request : DesignRequest
    models : dict of str to ArxModel
        The model each motor was designed on.
    motors : dict of str to MotorDesign
        With ``entry`` holding the step and the settling bound as well.
    steps : dict of str to StepAnalysis
        The simulated step of each motor, in the bound's settling band.
    loop_delay_ticks : int or None
        The loop delay the designs are for (None when the motors' model delays differ).
    recorded_loop_delay_ticks : int or None
        The loop delay the models' data was recorded in (their model file's), when known.
    loop_delay_note : str or None
        One line where the models' nk and the loop delay disagree (:func:`loop_delay_for`).
    """

    request: DesignRequest
    models: dict[str, ArxModel]
    motors: dict[str, MotorDesign]
    steps: dict[str, StepAnalysis] = field(default_factory=dict)
    loop_delay_ticks: int | None = None
    recorded_loop_delay_ticks: int | None = None
    loop_delay_note: str | None = None

    def entries(self) -> dict[str, dict[str, Any]]:
        """Per motor, the figures of ``design --json``."""
        return {m: d.entry for m, d in self.motors.items()}


def design_models(
    request: DesignRequest, models: ModelFile | dict[str, ArxModel], motors: tuple[str, ...]
) -> Designs:
    """Design every motor of ``motors`` on its model, with the simulated step and its bound."""
    request.check()
    check_models(models, motors)
    by_motor = {
        m: (models.motor(m) if isinstance(models, ModelFile) else models[m]) for m in motors
    }
    recorded = models.loop_delay_ticks if isinstance(models, ModelFile) else None
    loop_delay, note = loop_delay_for(request, by_motor, recorded, strict=False)
    designs: dict[str, MotorDesign] = {}
    steps: dict[str, StepAnalysis] = {}
    for m, model in by_motor.items():
        made = design_motor(request, model)
        step = simulate_step(made.controller, model, step_rad_s=request.step_rad_s,
                             extra_delay_ticks=request.extra_delay_ticks)  # fmt: skip
        bound = settling_bound(model, request.step_rad_s, voltage_limit_v=request.voltage_limit_v,
                               extra_delay_ticks=request.extra_delay_ticks)  # fmt: skip
        step = in_settling_band(step, model.period_s)  # the bound's band: max(2 %, one count)
        settle = step.info.settling_time_s
        entry = made.entry
        entry["step"] = step.to_dict()
        entry["settling_bound_s"] = bound.settling_time_s
        entry["settling_ratio"] = None if settle is None else settle / bound.settling_time_s
        # the loop the design is for (the model's recorded loop, or nk − 1, plus the extra delay)
        entry["settling_bound_loop_delay_ticks"] = (
            bound.loop_delay_ticks if loop_delay is None else loop_delay
        )
        designs[m] = made
        steps[m] = step
    return Designs(request, by_motor, designs, steps, loop_delay, recorded, note)


def controller_file(
    designs: Designs, model_path: str | Path, *, command: str, period_s: float
) -> ControllerFile:
    """The controller file of ``designs`` (designed on ``model_path``), ready to save.

    Raises
    ------
    InputError
        The motors' models have different input delays and no recorded loop delay they both
        fit: one file is for one loop.
    """
    loop_delay, _ = loop_delay_for(designs.request, designs.models,
                                   designs.recorded_loop_delay_ticks, strict=True)  # fmt: skip
    motors = {
        m: {**d.file_entry, "analysis": {k: v for k, v in d.entry.items() if k in ANALYSIS_KEYS}}
        for m, d in designs.motors.items()
    }
    request = designs.request
    return ControllerFile(
        method=request.method, period_s=period_s, voltage_limit_v=request.voltage_limit_v,
        model_path=str(model_path), model_sha256=file_sha256(model_path),
        request=request.file_request(), motors=motors,
        created=datetime.now(UTC).isoformat(timespec="seconds"), command=command,
        loop_delay_ticks=loop_delay,
    )  # fmt: skip
