"""Designs from a request, one path for ``cartctl design``, ``tune`` and the Python API: each
motor's runtime controller with its JSON and file entries (:func:`design_motor`), the simulated
step against the time-optimal bound (:func:`design_models`), and the controller file."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from cartctl.cart import nk_fits_loop_delay
from cartctl.data.modelfile import ModelFile
from cartctl.design.analysis import (
    StepAnalysis,
    in_settling_band,
    loop_analysis,
    settling_bound,
    simulate_step,
)
from cartctl.design.controller_ss import feedback_tf_coeffs
from cartctl.design.controllerfile import (
    ControllerFile,
    build_controller,
    common_loop_delay,
    file_sha256,
)
from cartctl.design.kalman import KalmanDesign, design_kalman
from cartctl.design.pi import design_pi, design_pi_bandwidth
from cartctl.design.poles import design_poles
from cartctl.design.request import NOISE_FIELDS, DesignRequest, check_loop_delay, parse_poles
from cartctl.errors import InputError
from cartctl.model import ArxModel
from cartctl.runtime.base import Controller

ANALYSIS_KEYS = (  # what a controller file keeps of a motor's design, under ``analysis``
    "phase_margin_deg", "gain_margin_db", "crossover_hz", "sensitivity_peak", "closed_loop_poles",
    "estimator_poles", "step", "settling_bound_s", "settling_ratio",
    "settling_bound_loop_delay_ticks",
)  # fmt: skip


@dataclass(frozen=True)
class MotorDesign:
    """One motor's design: the runtime controller (built from the file entry, as ``cartctl run``),
    its ``design --json`` entry, and its ``[motors.X]`` file table (without ``analysis``)."""

    controller: Controller
    entry: dict[str, Any]
    file_entry: dict[str, Any]


def design_motor(request: DesignRequest, model: ArxModel) -> MotorDesign:
    """Design one motor's controller as ``request`` asks."""
    extra = request.extra_delay_ticks
    noise = {f: getattr(request, f) for f in NOISE_FIELDS}
    if request.method == "pi":
        pm = request.phase_margin_deg
        given: dict[str, Any] = {"phase_margin_deg": pm, "extra_delay_ticks": extra}
        if request.bandwidth_hz is not None:
            d = design_pi_bandwidth(model, bandwidth_hz=request.bandwidth_hz, **given)
        else:
            d = design_pi(model, crossover_hz=request.crossover_hz, **given)
        num, den = d.controller_tf_coeffs()
        entry = d.to_dict()
        file_entry: dict[str, Any] = {"kp": d.kp, "ki": d.ki, "anti_windup": request.anti_windup,
                                      "controller_num": num, "controller_den": den}  # fmt: skip
        if request.estimator == "kalman":
            kalman = design_kalman(model, extra_delay_ticks=extra, **noise)
            entry["estimator_poles"] = [[p.real, p.imag] for p in kalman.poles()]
            file_entry["estimator"] = _kalman_entry(kalman)
    else:
        poles = parse_poles(request.poles) if request.poles else None
        spec = (None, None) if poles else (request.settling_time_s, request.overshoot_percent)
        placement = design_poles(
            model,
            poles=poles,
            settling_time_s=spec[0],
            overshoot_percent=spec[1],
            **noise,
            extra_delay_ticks=extra,
        )
        num, den = feedback_tf_coeffs(placement)
        file_entry = {"K": placement.K, "Ki": placement.Ki, "Kr": placement.Kr,
                      "controller_num": num, "controller_den": den,
                      "closed_loop_poles": [[p.real, p.imag] for p in placement.poles],
                      "estimator": _kalman_entry(placement.estimator)}  # fmt: skip
        loop = loop_analysis(num, den, model, extra)
        keys = ("phase_margin_deg", "gain_margin_db", "crossover_hz", "sensitivity_peak")
        entry = {
            **placement.to_dict(),
            **{k: loop[k] for k in (*keys, "sensitivity_peak_db")},
            "controller_num": num.tolist(),
            "controller_den": den.tolist(),
        }
    limit = request.voltage_limit_v
    controller = build_controller(request.method, file_entry, model.period_s, limit)
    return MotorDesign(controller, entry, file_entry)


def _kalman_entry(design: KalmanDesign) -> dict[str, Any]:
    """The estimator as a file stores it; ``timing_noise_std_ticks`` only when not 0 (files
    from before it stay the same)."""
    timing = design.timing_noise_std_ticks
    return {
        f.name: getattr(design, f.name)
        for f in fields(design)
        if timing or f.name != "timing_noise_std_ticks"
    }


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

    In order: ``--loop-delay`` if it fits every model (InputError otherwise); the loop delay the
    models were ``recorded`` in plus the extra delay, when every nk is that or one more; else the
    models' common nk − 1 + extra delay. Motors whose nk differ then give None, or with
    ``strict`` an InputError: a controller file is for one loop.
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
) -> dict[str, ArxModel]:
    """The model of each motor, refused before any design work where it is unstable (one line
    naming the file as ``name``, by default the model file's path)."""
    if name is None and isinstance(models, ModelFile) and models.path:
        name = str(models.path)
    where = f"{name}: " if name else ""
    by_motor = {m: models.motor(m) if isinstance(models, ModelFile) else models[m] for m in motors}
    for m, model in by_motor.items():
        if not model.is_stable():
            raise InputError(
                f"{where}motor {m}'s model is unstable (pole at |z| = {model.pole_radius():.4g}); "
                "a design needs a stable model (its simulated step and settling bound run on "
                "it): identify it again"
            )
    return by_motor


@dataclass(frozen=True)
class Designs:
    """The designs of the motors asked for, per motor (model, design, simulated step in the
    bound's settling band), with :func:`loop_delay_for`'s loop delay (None when the models'
    delays differ) and note."""

    request: DesignRequest
    models: dict[str, ArxModel]
    motors: dict[str, MotorDesign]
    steps: dict[str, StepAnalysis]
    loop_delay_ticks: int | None
    loop_delay_note: str | None

    def entries(self) -> dict[str, dict[str, Any]]:
        """Per motor, the figures of ``design --json``."""
        return {m: d.entry for m, d in self.motors.items()}


def design_models(
    request: DesignRequest, models: ModelFile | dict[str, ArxModel], motors: tuple[str, ...]
) -> Designs:
    """Design every motor of ``motors`` on its model, with the simulated step and its bound."""
    request.check()
    by_motor = check_models(models, motors)
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
        made.entry["step"] = step.to_dict()
        made.entry["settling_bound_s"] = bound.settling_time_s
        made.entry["settling_ratio"] = None if settle is None else settle / bound.settling_time_s
        # the loop the design is for (the model's recorded loop, or nk − 1, plus the extra delay)
        made.entry["settling_bound_loop_delay_ticks"] = (
            bound.loop_delay_ticks if loop_delay is None else loop_delay
        )
        designs[m] = made
        steps[m] = step
    return Designs(request, by_motor, designs, steps, loop_delay, note)


def controller_file(
    designs: Designs, model_path: str | Path, *, command: str, period_s: float
) -> ControllerFile:
    """The controller file of ``designs`` (designed on ``model_path``), ready to save;
    InputError when the motors' models fit no one loop delay."""
    loop_delay = designs.loop_delay_ticks
    if loop_delay is None:  # the models' delays differ: the reason, as an InputError
        loop_delay_for(designs.request, designs.models)
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
