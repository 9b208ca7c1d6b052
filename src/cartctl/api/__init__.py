"""cartctl from Python: the functions behind the commands, for notebooks and scripts.

Each function takes the command line's path (``cartctl excite``, ``identify``, ``design``,
``run --fast``), so a notebook and a shell give the same numbers, and raises
:class:`~cartctl.errors.CartctlError` with the CLI's one-line messages. The results are in
:mod:`cartctl.api.results`; the user guide (docs/python-api.md) walks through a session."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from contextlib import suppress
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from cartctl.api.results import Design, Identification, MotorResult, SimulationResult
from cartctl.choices import DEFAULT_MODEL, check_duration, check_finite, is_number, is_whole
from cartctl.data.modelfile import ModelFile, load_models, save_models
from cartctl.data.outputs import check_output_file
from cartctl.data.read import read_trace
from cartctl.data.trace import MOTORS, Trace, parse_mapping
from cartctl.design.controllerfile import ControllerFile, load_controller
from cartctl.design.make import design_models
from cartctl.design.request import OPTIONS, DesignRequest
from cartctl.errors import InputError, PlantError
from cartctl.identification.pipeline import IdentifyRequest, Prefilter
from cartctl.identification.pipeline import identify as identify_traces
from cartctl.plants.factory import SIMULATED, check_plant_options, make_plant, plant_kind
from cartctl.reference import check_reference
from cartctl.runtime.loop import run_in_memory
from cartctl.session.prepare import prepare_run
from cartctl.sinks.summary import trace_metrics

__all__ = [
    "Design",
    "Identification",
    "MotorResult",
    "SimulationResult",
    "design_pi",
    "design_poles",
    "excite",
    "identify",
    "load_model",
    "load_trace",
    "save_model",
    "simulate",
]


def load_trace(path: str | Path, map: str | Mapping[str, str] | None = None) -> Trace:
    """Read an experiment: a trace CSV or a QRoboticsCenter log (as every command does).

    Parameters
    ----------
    map : str or mapping, optional
        Which log channel is which column: ``"voltage_a=FloatIn2,speed_a=FloatIn0"`` or a dict.
    """
    if map is not None and not isinstance(map, str | Mapping):
        shown = "'voltage_a=FloatIn2,speed_a=FloatIn0'"
        raise InputError(f"map must be text like {shown} or a dict, got {map!r}")
    return read_trace(path, parse_mapping(map) if isinstance(map, str) else map)


def _check_simulated(
    plant: str, what: str, model: object, preset: str, noise: float, seed: Any
) -> None:
    if not isinstance(plant, str) or plant_kind(plant) not in SIMULATED:
        raise InputError(f"{what} runs on 'sim' or 'physics[:actuation_ms=X]', not '{plant}'")
    if seed is not None and not (is_whole(seed) and seed >= 0):  # as --seed (else numpy's error)
        raise InputError(f"a seed is a whole number >= 0, got {seed!r}")
    options = {
        "--model": model is not None,
        "--preset": preset != "ground",
        "--seed": seed is not None,
    }
    given = [o for o, on in options.items() if on]
    # the command line's lines: --noise in range, no plant option its plant does not use
    check_plant_options(plant, noise_std_rad_s=noise, given=given)


def excite(
    *,
    plant: str = "physics",
    signal: str = "square",
    amplitude_v: float = 10.0,
    cycles: int | None = None,
    duration_s: float | None = None,
    motor: str = "both",
    model: str | Path | None = None,
    preset: str = "ground",
    noise_std_rad_s: float = 0.0,
    seed: int | None = None,
) -> Trace:
    """Record an excitation experiment on a simulated plant, as ``cartctl excite`` does.

    Parameters
    ----------
    plant : {'physics', 'physics:actuation_ms=X', 'sim'}
        The physical simulator (with ``preset``; ``cartctl excite`` defaults to sim) or the ARX
        models of ``model``.
    signal : {'square', 'step', 'prbs', 'multisine', 'chirp'}
    amplitude_v : float
        Peak voltage (V), at most the supply's 12 V.
    cycles : int, optional
        Repetitions of the square cycle (3 s each; default 5) or of the multisine period.
    duration_s : float, optional
        Length of the step, prbs, chirp or multisine (s).
    motor : {'both', 'a', 'b'}
        Which motor gets the signal; the other stays at 0 V.
    noise_std_rad_s, seed
        Speed measurement noise (rad/s) and its seed.

    Returns
    -------
    Trace
        The trace columns, with ``true_speed_a``/``true_speed_b`` from the simulator.
    """
    from cartctl.cart import SUPPLY_V
    from cartctl.runtime.loop import run_experiment
    from cartctl.signals import make_signal

    _check_simulated(plant, "excite", model, preset, noise_std_rad_s, seed)
    if motor not in ("a", "b", "both"):
        raise InputError(f"motor must be 'a', 'b' or 'both', got {motor!r}")
    if check_finite(amplitude_v, "amplitude_v") > SUPPLY_V:
        raise InputError(f"amplitude_v {amplitude_v} V is beyond the cart's ±{SUPPLY_V:g} V supply")
    if duration_s is not None and signal == "square":
        raise InputError("duration_s does not apply to the square signal; use cycles (3 s each)")
    if duration_s is not None:
        check_duration(duration_s)
    volts = make_signal(signal, amplitude_v, cycles=cycles, duration_s=duration_s)
    the_plant, description = make_plant(plant, model_path=model or DEFAULT_MODEL, preset=preset,
                                        noise_std_rad_s=noise_std_rad_s, seed=seed,
                                        motors="ab" if motor == "both" else motor)  # fmt: skip
    per_motor = (volts if motor in (m, "both") else np.zeros_like(volts) for m in MOTORS)
    result = run_experiment(the_plant, *per_motor, source=description)
    if result.interrupted:  # a notebook's interrupt stops the cell, not just the experiment
        raise KeyboardInterrupt
    if result.failure:
        raise PlantError(result.failure)
    return result.trace


def identify(
    traces: Trace | str | Path | Sequence[Trace | str | Path],
    *,
    motors: Sequence[str] = MOTORS,
    delay: int | str = 2,
    na: int = 2,
    nb: int = 2,
    method: str = "arx",
    prefilter_hz: float | None = None,
    prefilter_order: int = 6,
    zero_phase: bool = False,
    average: bool = False,
    loop_delay_ticks: int | None = None,
) -> Identification:
    """Fit the motors' ARX models from experiments, as ``cartctl identify`` does.

    Parameters
    ----------
    delay : int or 'auto'
        Input delay nk (2 on board, as in the report), or 'auto' to estimate it.
    method : {'arx', 'oe'}
    prefilter_hz : float, optional
        Butterworth prefilter cut-off (Hz); None: no prefilter.
    average : bool
        Average whole excitation cycles before the fit.
    loop_delay_ticks : int, optional
        Ticks from a measurement to the voltage it leads to being on the motor in the loop that
        recorded the data, written into the model for design. Default: from the ``.meta.toml``
        beside traces given by path, else unknown.
    """
    from cartctl.data.trace import loop_delay_of

    if not isinstance(traces, Trace | str | Path | Iterable):
        raise InputError(f"identify takes a trace, its path or a list of them, not {traces!r}")
    items = [traces] if isinstance(traces, Trace | str | Path) else list(traces)
    loaded = [t if isinstance(t, Trace) else read_trace(t) for t in items]
    if loop_delay_ticks is None:
        loop_delay_ticks = loop_delay_of([t for t in items if not isinstance(t, Trace)])
    if delay != "auto" and not is_whole(delay):
        raise InputError(f"delay must be a whole number of ticks or 'auto', got {delay!r}")
    shape = {"prefilter_order": prefilter_order != Prefilter.order, "zero_phase": zero_phase}
    if prefilter_hz is None and any(shape.values()):  # as identify's --order without --prefilter
        given = [name for name, differs in shape.items() if differs]
        raise InputError(f"{' and '.join(given)} need{'s' * (len(given) == 1)} prefilter_hz")
    request = IdentifyRequest(
        motors=tuple(motors), na=na, nb=nb, delay=None if delay == "auto" else int(delay),
        prefilter=None if prefilter_hz is None else Prefilter(
            order=prefilter_order, cutoff_hz=prefilter_hz, zero_phase=zero_phase),
        method=method, average=average, loop_delay_ticks=loop_delay_ticks,
    )  # fmt: skip
    result = identify_traces(loaded, request)
    out = {}
    for m, r in result.motors.items():
        fit = r.chosen
        out[m] = MotorResult(
            model=fit.model, theta=np.asarray(fit.model.theta, dtype=float),
            theta_std=np.asarray(fit.theta_std, dtype=float),
            fit_simulation_percent=fit.fit_simulation_percent,
            fit_prediction_percent=fit.fit_prediction_percent, tf=fit.model.to_tf(), details=r,
        )  # fmt: skip
    sources = tuple(str(t.source) if t.source else "<trace>" for t in loaded)
    return Identification(out, result, request, sources)


def load_model(path: str | Path) -> ModelFile:
    """Read a model file (``models/ground.toml``): ``load_model(p).motor("a")`` is an ArxModel."""
    return load_models(path)


def save_model(models: ModelFile | Identification, path: str | Path) -> Path:
    """Write a model file (from :func:`load_model` or :func:`identify`); returns its path."""
    if not isinstance(models, ModelFile | Identification):
        raise InputError(f"save_model takes load_model's or identify's result, not {models!r}")
    file = models.model_file() if isinstance(models, Identification) else models
    save_models(file, check_output_file(path, "save"))  # as --out is checked
    return Path(path)


def _design(model: str | Path | ModelFile, request: DesignRequest, motors: Sequence[str]) -> Design:
    if isinstance(model, ModelFile) and model.path is not None:
        model = model.path
    if not isinstance(model, str | Path):  # an unsaved model file, an Identification …
        raise InputError("design from a saved model file: give its path (save_model first)")
    given = list(motors) if isinstance(motors, Iterable) and not isinstance(motors, str) else motors
    if not given or not isinstance(given, str | list) or not set(given) <= set(MOTORS):
        raise InputError(f"motors must be 'a' and/or 'b', got {given!r}")  # 'both' as itself
    models = load_models(model)
    return Design(design_models(request, models, tuple(given)), Path(model), models.period_s)


def _request(method: str, options: dict[str, Any]) -> DesignRequest:
    """The request of ``options``, a number given for a number of the command line as the float
    it parses (``8`` and numpy's ``float64(8)`` are ``8.0``, in the controller file and its
    command too; bools stay, to be refused)."""
    names = {f.name for f in fields(DesignRequest)} - {"method"}
    for name in sorted(options.keys() - names):  # (else a TypeError naming DesignRequest)
        flag = "--" + name.replace("_", "-")  # an option by its command-line name?
        known = [f"{flag} is {f}" for f, o in OPTIONS.items() if o == flag]
        hint = known[0] if known else "the options are " + ", ".join(sorted(names))
        raise InputError(f"design_{method} has no option {name!r}; {hint}")
    floats = {f.name for f in fields(DesignRequest) if str(f.type).startswith("float")}
    for name, value in options.items():
        if name in floats and is_number(value):
            with suppress(OverflowError):  # beyond any float: its range refuses it
                options[name] = float(value)
    return DesignRequest(method=method, **options)


def design_pi(
    model: str | Path | ModelFile, *, motors: Sequence[str] = MOTORS, **options: Any
) -> Design:
    """A PI per motor (``cartctl design --method pi``).

    ``options`` are the fields of :class:`~cartctl.design.request.DesignRequest`:
    ``phase_margin_deg``, ``crossover_hz`` or ``bandwidth_hz``, ``anti_windup``, ``estimator``,
    ``extra_delay_ticks``, ``voltage_limit_v``, ``step_rad_s`` …"""
    return _design(model, _request("pi", options), motors)


def design_poles(
    model: str | Path | ModelFile, *, motors: Sequence[str] = MOTORS, **options: Any
) -> Design:
    """Pole placement with a Kalman estimator per motor (``cartctl design --method poles``).

    ``options``: ``settling_time_s`` and ``overshoot_percent`` or ``poles``, the estimator's
    ``process_noise_std_v``/``bias_drift_std_v``, ``extra_delay_ticks`` … (see
    :class:`~cartctl.design.request.DesignRequest`)."""
    return _design(model, _request("poles", options), motors)


def simulate(
    controller: Design | str | Path | ControllerFile,
    *,
    plant: str = "sim",
    reference: str = "step:10",
    duration_s: float = 2.0,
    model: str | Path | None = None,
    preset: str = "ground",
    noise_std_rad_s: float = 0.0,
    seed: int | None = None,
    allow_unstable: bool = False,
    allow_delay_mismatch: bool = False,
) -> SimulationResult:
    """Run a controller in the simulated loop as ``cartctl run --fast`` does (and refuses).

    Parameters
    ----------
    plant : {'sim', 'physics', 'physics:actuation_ms=X'}
        The ARX models of ``model`` (default: the model the controller was designed on, where
        ``cartctl run`` takes models/ground.toml), or the physical simulator with ``preset``
        (and the actuation timing, ms).
    reference : str
        A reference spec (``step:10``, ``square:8:2``, ``file:ref.csv`` …).
    duration_s : float
        Run time (s); ``cartctl run`` runs 5 s by default.
    allow_unstable, allow_delay_mismatch : bool
        Run what is refused without ``--allow-unstable`` or ``--allow-delay-mismatch``, the
        options the refusals name: an unstable model, or another loop delay than designed for.
    """
    _check_simulated(plant, "simulate", model, preset, noise_std_rad_s, seed)
    check_duration(duration_s)
    check_reference(reference)  # named as run names it
    if isinstance(controller, Design):
        file = replace(controller.controller_file(), path=None)
        name = f"{controller.request.method.upper()} designed on {controller.model_path}"
    elif isinstance(controller, ControllerFile):
        file = controller
        name = str(file.path) if file.path else f"{file.method.upper()} controller"
    elif isinstance(controller, str | Path):
        file = load_controller(controller)
        name = str(controller)
    else:
        kind = type(controller).__name__
        raise InputError(f"simulate runs a Design, a controller file or its path, not {kind}")
    # what cartctl run refuses, refused here with the same line (cartctl.session)
    prepared = prepare_run(file, given=name, plant=plant, duration_s=float(duration_s),
                           reference=reference, model=model or file.model_path, preset=preset,
                           noise_std_rad_s=noise_std_rad_s, seed=seed,
                           allow_unstable=allow_unstable,
                           allow_delay_mismatch=allow_delay_mismatch)  # fmt: skip
    period_s = prepared.period_s
    columns, state = run_in_memory(prepared.plant, prepared.controllers, prepared.references,
                                   period_s=period_s,
                                   voltage_limit_v=prepared.voltage_limit_v)  # fmt: skip
    return SimulationResult(columns, trace_metrics(columns, period_s), state.failure,
                            controller=name, plant=plant, reference=reference)  # fmt: skip
