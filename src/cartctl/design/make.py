"""Designs from a request, one path for ``cartctl design``, ``tune`` and the Python API: each
motor's runtime controller with its JSON and file entries (:func:`design_motor`), the simulated
step against the time-optimal bound and the loop analysis (:func:`design_models`), and the
controller file."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import nk_fits_loop_delay
from cartctl.data.modelfile import ModelFile
from cartctl.design.analysis import (
    DEFAULT_DISTURBANCE_V,
    DisturbanceResponse,
    StepAnalysis,
    in_settling_band,
    loop_analysis,
    settling_bound,
    simulate_disturbance,
    simulate_step,
)
from cartctl.design.controller_ss import controller_state_space, feedback_tf_coeffs
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
from cartctl.model import ArxModel, check_input_delay, pole_damping
from cartctl.runtime.base import Controller

LIGHT_DAMPING = 0.1  # a closed-loop pole with a damping ratio ζ below this rings: a warning

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
    estimator = {f: getattr(request, f) for f in NOISE_FIELDS} | {"extra_delay_ticks": extra}
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
            kalman = design_kalman(model, **estimator)
            entry["estimator_poles"] = [[p.real, p.imag] for p in kalman.poles()]
            file_entry["estimator"] = _kalman_entry(kalman)
            # the margins of the loop as it runs (the PI on its estimate), not the bare PI's
            whole = controller_state_space("pi", file_entry, model.period_s).feedback_tf()
            margins = loop_analysis(*whole, model, extra)
            entry |= {k: margins[k] for k in ("phase_margin_deg", "gain_margin_db", "crossover_hz")}
    else:
        poles = parse_poles(request.poles) if request.poles else None
        spec = (None, None) if poles else (request.settling_time_s, request.overshoot_percent)
        placement = design_poles(
            model, poles=poles, settling_time_s=spec[0], overshoot_percent=spec[1], **estimator
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
    try:  # the checks run applies to the file's estimator (its variances, its decay)
        controller = build_controller(request.method, file_entry, model.period_s, limit)
    except ValueError as exc:
        why = str(exc).removesuffix("; redesign the controller")
        raise InputError(
            f"the design's estimator is unusable: {why}; try other "
            "--process-noise-v, --bias-drift-v or --measurement-noise"
        ) from None
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


@dataclass(frozen=True, eq=False)
class MotorAnalysis:
    """One motor's loop analysis (:func:`analyse_motor`): the open loop L on a frequency grid
    (``freq_hz``, 1 mHz to Nyquist) with the peaks Ms = max|S| and Mt = max|T| and where they are
    (Hz; 0 for T(1) = 1 of integral action), the simulated load-disturbance step, and the pole
    table."""

    freq_hz: NDArray[np.float64]
    loop: NDArray[np.complex128]
    sensitivity_peak: float
    sensitivity_peak_hz: float
    complementary_peak: float
    complementary_peak_hz: float
    disturbance: DisturbanceResponse
    pole_table: list[dict[str, Any]]
    motor: str = "a"

    def entry(self) -> dict[str, Any]:
        """The keys this analysis adds to (or replaces in) a motor's ``design --json`` entry;
        ``sensitivity_peak`` is the loop's as it runs (the PI's with its Kalman estimator)."""
        ms, mt = self.sensitivity_peak, self.complementary_peak
        return {
            "sensitivity_peak": ms,
            "sensitivity_peak_db": 20.0 * math.log10(ms),
            "sensitivity_peak_hz": self.sensitivity_peak_hz,
            "complementary_peak": mt,
            "complementary_peak_db": 20.0 * math.log10(mt),
            "complementary_peak_hz": self.complementary_peak_hz,
            "sensitivity_distance": 1.0 / ms,
            "disturbance": self.disturbance.to_dict(),
            "closed_loop_pole_table": self.pole_table,
            "warnings": self.warnings,
        }

    @property
    def warnings(self) -> list[str]:
        """A line naming the least damped closed-loop pole when its ζ is below ``LIGHT_DAMPING``
        (an undefined ζ, at z = 0 or z = 1, is none)."""
        table = self.pole_table
        light = [r for r in table if r["damping"] is not None and r["damping"] < LIGHT_DAMPING]
        if not light:
            return []
        worst = min(light, key=lambda r: r["damping"])
        z = f"{worst['re']:.4f}" + ("" if worst["im"] == 0.0 else f" ± {abs(worst['im']):.4f}j")
        freq = "" if worst["freq_hz"] is None else f" at {worst['freq_hz']:.2f} Hz"
        others = len({(r["re"], abs(r["im"])) for r in light}) - 1
        more = f" ({others} more pole(s) below {LIGHT_DAMPING:g})" if others else ""
        return [
            f"motor {self.motor}: closed-loop pole z = {z} has damping ζ = "
            f"{worst['damping']:.3f} < {LIGHT_DAMPING:g}{more}: the loop rings{freq} for many "
            "periods"
        ]


def analyse_motor(
    made: MotorDesign, model: ArxModel, request: DesignRequest, disturbance_v: float, motor: str
) -> MotorAnalysis:
    """The loop analysis of one motor's design, with a load step of ``disturbance_v`` (V).

    The controller is taken whole, as the loop runs it (:mod:`cartctl.design.controller_ss`),
    broken at the plant input: L = C_fb·G·z^(−extra), S = 1/(1 + L), T = L/(1 + L). Margins and
    Ms = max|S| are python-control's (:func:`~cartctl.design.analysis.loop_analysis`); Mt =
    max|T| is found on a frequency grid up to Nyquist, refined by ``minimize_scalar``.
    """
    from scipy import optimize

    extra = request.extra_delay_ticks
    controller = controller_state_space(request.method, made.file_entry, model.period_s)

    def loop_at(freq_hz: NDArray[np.float64]) -> NDArray[np.complex128]:
        z = np.exp(2j * np.pi * freq_hz * model.period_s)
        return controller.feedback_response(z) * model.response_at(z) * z ** (-extra)

    def minus_t(f: float) -> float:
        ell = loop_at(np.array([f]))[0]
        return -float(abs(ell / (1.0 + ell)))

    freq = np.geomspace(1e-3, 0.5 / model.period_s, 2000)  # from 1 mHz: integral action is at 0
    loop = loop_at(freq)
    on_grid = np.abs(loop / (1.0 + loop))
    i = int(np.argmax(on_grid))
    mt, mt_hz = float(on_grid[i]), float(freq[i])
    bounds = (freq[max(i - 1, 0)], freq[min(i + 1, freq.size - 1)])
    res = optimize.minimize_scalar(
        minus_t, bounds=bounds, method="bounded", options={"xatol": 1e-9}
    )
    if res.success and -res.fun > mt:
        mt, mt_hz = float(-res.fun), float(res.x)
    margins = loop_analysis(*controller.feedback_tf(), model, extra)
    dist = simulate_disturbance(
        made.controller, model, disturbance_v=disturbance_v, extra_delay_ticks=extra
    )
    table = []  # per pole: damping and natural frequency of its s = ln(z)/Ts
    for re, im in made.entry["closed_loop_poles"]:
        damping, freq_hz = pole_damping(complex(re, im), model.period_s)
        table.append({"re": re, "im": im, "damping": damping, "freq_hz": freq_hz})
    ms, ms_hz = margins["sensitivity_peak"], margins["sensitivity_peak_hz"]
    mt_hz = 0.0 if i == 0 else mt_hz  # Mt at 0 Hz: integral action
    return MotorAnalysis(freq, loop, ms, ms_hz, mt, mt_hz, dist, table, motor)


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
        check_input_delay(model.nk, f"{where}motor {m}'s model: ")
        if not any(model.b):
            raise InputError(f"{where}motor {m}'s model has b = 0: no voltage moves it")
        if not model.is_stable():
            raise InputError(
                f"{where}motor {m}'s model is {model.stability()} (pole at |z| = "
                f"{model.pole_radius():.4g}); a design needs a stable model, every pole inside "
                "the unit circle (its simulated step and settling bound run on it): identify it "
                "again"
            )
    return by_motor


@dataclass(frozen=True)
class Designs:
    """The designs of the motors asked for, per motor (model, design, simulated step in the
    bound's settling band, loop analysis), with :func:`loop_delay_for`'s loop delay (None when
    the models' delays differ) and note."""

    request: DesignRequest
    models: dict[str, ArxModel]
    motors: dict[str, MotorDesign]
    steps: dict[str, StepAnalysis]
    analyses: dict[str, MotorAnalysis]
    loop_delay_ticks: int | None
    loop_delay_note: str | None

    def entries(self) -> dict[str, dict[str, Any]]:
        """Per motor, the figures of ``design --json``."""
        return {m: d.entry for m, d in self.motors.items()}


def design_models(
    request: DesignRequest,
    models: ModelFile | dict[str, ArxModel],
    motors: tuple[str, ...],
    *,
    disturbance_v: float = DEFAULT_DISTURBANCE_V,
) -> Designs:
    """Design every motor of ``motors`` on its model, with the simulated step and its bound, and
    analyse its loop (:func:`analyse_motor`, a load step of ``disturbance_v`` V); the analysis
    keys go into each motor's ``design --json`` entry, and so into the controller file's
    ``analysis`` (the loop's Ms as it runs)."""
    request.check()
    by_motor = check_models(models, motors)
    recorded = models.loop_delay_ticks if isinstance(models, ModelFile) else None
    loop_delay, note = loop_delay_for(request, by_motor, recorded, strict=False)
    designs: dict[str, MotorDesign] = {}
    steps: dict[str, StepAnalysis] = {}
    analyses: dict[str, MotorAnalysis] = {}
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
        analyses[m] = analyse_motor(made, model, request, disturbance_v, m)
        made.entry.update(analyses[m].entry())
        designs[m] = made
        steps[m] = step
    return Designs(request, by_motor, designs, steps, analyses, loop_delay, note)


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
