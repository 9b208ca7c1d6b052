"""cartctl from Python: the functions behind the commands, for notebooks and scripts.

From a recorded experiment to a closed-loop step::

    import cartctl

    trace = cartctl.load_trace("logs/square.csv")
    ident = cartctl.identify(trace)                    # the report's ARX, nk = 2
    print(ident["a"].theta, ident["a"].tf)             # θ and a python-control TransferFunction
    ident.save("models/mine.toml")
    design = cartctl.design_pi("models/mine.toml", phase_margin_deg=65, crossover_hz=4)
    run = cartctl.simulate(design, plant="physics", reference="step:10", duration_s=2)
    run.plot()                                         # speed, reference and voltage (matplotlib)

Every function is the path the command line takes (``cartctl identify``, ``design``,
``run --fast``), so a notebook and a shell give the same numbers. Errors are
:class:`~cartctl.errors.CartctlError` with the one-line messages of the CLI.
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.data import Trace, parse_mapping, read_trace
from cartctl.design.build import build_controllers
from cartctl.design.controllerfile import ControllerFile, load_controller, save_controller
from cartctl.design.make import Designs, controller_file, design_models
from cartctl.design.request import DesignRequest
from cartctl.errors import InputError
from cartctl.identification.pipeline import (
    IdentifyRequest,
    IdentifyResult,
    MotorIdentification,
    model_file,
)
from cartctl.identification.pipeline import identify as identify_traces
from cartctl.identification.prefilter import Prefilter
from cartctl.model import ArxModel
from cartctl.modelfile import ModelFile, load_models, save_models
from cartctl.plants.factory import make_plant
from cartctl.reference import ReferenceSchedule
from cartctl.runtime.fast import run_in_memory
from cartctl.sinks.summary import trace_metrics

__all__ = [
    "Design",
    "Identification",
    "MotorResult",
    "SimulationResult",
    "design_pi",
    "design_poles",
    "identify",
    "load_model",
    "load_trace",
    "save_model",
    "simulate",
]

MOTORS = ("a", "b")


def load_trace(path: str | Path, map: str | Mapping[str, str] | None = None) -> Trace:
    """Read an experiment: contract-1 CSV or a QRoboticsCenter log (as every command does).

    Parameters
    ----------
    path : str or Path
    map : str or mapping, optional
        Which log channel is which column: ``"voltage_a=FloatIn2,speed_a=FloatIn0"`` or a dict.
    """
    mapping = parse_mapping(map) if isinstance(map, str) else map
    return read_trace(path, mapping)


@dataclass(frozen=True)
class MotorResult:
    """One motor's identified model.

    Attributes
    ----------
    model : ArxModel
    theta, theta_std : ndarray
        The report's θ = [c, d, a, b] (for na = nb = 2) and its standard deviations.
    fit_simulation_percent, fit_prediction_percent : float
    tf : control.TransferFunction
        The model as python-control's discrete transfer function (dt = Ts).
    details : MotorIdentification
        Everything ``identify`` computed (ARX, OE, the delay estimate…).
    """

    model: ArxModel
    theta: NDArray[np.float64]
    theta_std: NDArray[np.float64]
    fit_simulation_percent: float
    fit_prediction_percent: float
    tf: Any
    details: MotorIdentification


@dataclass(frozen=True)
class Identification:
    """Per-motor results of :func:`identify` (``result["a"]``), saveable as a model file."""

    motors: dict[str, MotorResult]
    result: IdentifyResult
    request: IdentifyRequest
    sources: tuple[str, ...]

    def __getitem__(self, motor: str) -> MotorResult:
        return self.motors[motor]

    def model_file(self) -> ModelFile:
        """The models with their provenance, as ``identify --out`` writes them."""
        return model_file(
            self.result, list(self.sources), self.request, source="cartctl.identify()"
        )

    def save(self, path: str | Path) -> Path:
        """Write the model file; returns its path."""
        save_models(self.model_file(), path)
        return Path(path)


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
) -> Identification:
    """Fit the motors' ARX models from experiments, as ``cartctl identify`` does.

    Parameters
    ----------
    traces : Trace, path, or a sequence of them
    motors : sequence of {'a', 'b'}
    delay : int or 'auto'
        Input delay nk (2 on board, as in the report), or 'auto' to estimate it.
    na, nb : int
        Model orders.
    method : {'arx', 'oe'}
    prefilter_hz : float, optional
        Butterworth prefilter cut-off (Hz); None: no prefilter.
    prefilter_order : int
    zero_phase : bool
    average : bool
        Average whole excitation cycles before the fit.
    """
    items = [traces] if isinstance(traces, Trace | str | Path) else list(traces)
    loaded = [t if isinstance(t, Trace) else read_trace(t) for t in items]
    if delay != "auto" and not isinstance(delay, int):
        raise InputError(f"delay must be a whole number of ticks or 'auto', got {delay!r}")
    request = IdentifyRequest(
        motors=tuple(motors), na=na, nb=nb, delay=None if delay == "auto" else int(delay),
        prefilter=None if prefilter_hz is None else Prefilter(
            order=prefilter_order, cutoff_hz=prefilter_hz, zero_phase=zero_phase),
        method=method, average=average,
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
    if isinstance(models, Identification):
        return models.save(path)
    save_models(models, path)
    return Path(path)


@dataclass(frozen=True)
class Design:
    """Controllers designed on a model file, as ``cartctl design`` makes them.

    Attributes
    ----------
    designs : Designs
        Per motor: the runtime controller, its figures (``entry``) and its simulated step.
    model_path : Path
        The model file designed on (recorded in the controller file).
    period_s : float
    """

    designs: Designs
    model_path: Path
    period_s: float

    @property
    def request(self) -> DesignRequest:
        return self.designs.request

    def __getitem__(self, motor: str) -> dict[str, Any]:
        """One motor's figures: gains, margins, closed-loop poles, the simulated step."""
        return self.designs.motors[motor].entry

    def controller_file(self) -> ControllerFile:
        """The controller file, as ``cartctl design --out`` writes it."""
        command = "cartctl " + shlex.join(["design", *self.request.to_argv(str(self.model_path))])
        return controller_file(self.designs, self.model_path, command=command,
                               period_s=self.period_s)  # fmt: skip

    def save(self, path: str | Path) -> Path:
        """Write the controller file; ``cartctl run --controller PATH`` runs it."""
        save_controller(self.controller_file(), path)
        return Path(path)


def _design(model: str | Path | ModelFile, request: DesignRequest, motors: Sequence[str]) -> Design:
    if isinstance(model, ModelFile):
        if model.path is None:
            raise InputError("design from a saved model file: give its path (save_model first)")
        model = model.path
    models = load_models(model)
    return Design(design_models(request, models, tuple(motors)), Path(model), models.period_s)


def design_pi(
    model: str | Path | ModelFile, *, motors: Sequence[str] = MOTORS, **options: Any
) -> Design:
    """A PI per motor (``cartctl design --method pi``).

    ``options`` are the fields of :class:`~cartctl.design.request.DesignRequest`:
    ``phase_margin_deg``, ``crossover_hz`` or ``bandwidth_hz``, ``anti_windup``, ``estimator``,
    ``extra_delay_ticks``, ``voltage_limit_v``, ``step_rad_s`` …
    """
    return _design(model, DesignRequest(method="pi", **options), motors)


def design_poles(
    model: str | Path | ModelFile, *, motors: Sequence[str] = MOTORS, **options: Any
) -> Design:
    """Pole placement with a Kalman estimator per motor (``cartctl design --method poles``).

    ``options``: ``settling_time_s`` and ``overshoot_percent`` or ``poles``, the estimator's
    ``process_noise_std_v``/``bias_drift_std_v``, ``extra_delay_ticks`` … (see
    :class:`~cartctl.design.request.DesignRequest`).
    """
    return _design(model, DesignRequest(method="poles", **options), motors)


@dataclass(frozen=True)
class SimulationResult:
    """A simulated closed-loop run.

    Attributes
    ----------
    columns : dict of str to ndarray
        The trace's columns (contract 1 and the loop's: ``time_s``, ``voltage_a``, ``speed_a``,
        ``reference_a``, ``estimate_a``, ``true_speed_a`` …); the last row is the stop row.
    summary : dict
        The run summary of ``cartctl run --json`` (overshoot, settling, errors per motor).
    failure : str or None
    """

    columns: dict[str, NDArray[np.float64]]
    summary: dict[str, Any]
    failure: str | None = None

    def to_dataframe(self) -> Any:
        """The columns as a pandas DataFrame (needs pandas)."""
        try:
            import pandas as pd
        except ImportError:
            raise InputError("to_dataframe needs pandas: pip install pandas") from None
        return pd.DataFrame(self.columns)

    def plot(self, motor: str = "a", ax: Any = None) -> Any:
        """Speed, reference and voltage of one motor over time (matplotlib); returns the figure."""
        import matplotlib.pyplot as plt

        c = self.columns
        fig, (top, bottom) = (
            plt.subplots(2, 1, sharex=True, figsize=(8, 5)) if ax is None else (ax.figure, ax)
        )
        top.plot(c["time_s"], c[f"reference_{motor}"], "k--", label="reference")
        top.plot(c["time_s"], c[f"speed_{motor}"], label="measured speed")
        if f"true_speed_{motor}" in c:
            top.plot(c["time_s"], c[f"true_speed_{motor}"], label="true speed")
        top.set_ylabel("rad/s")
        top.legend(loc="lower right")
        bottom.step(c["time_s"], c[f"voltage_{motor}"], where="post")
        bottom.set_ylabel("V")
        bottom.set_xlabel("time (s)")
        return fig


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
) -> SimulationResult:
    """Run a controller in the simulated loop, as ``cartctl run --fast`` does.

    Parameters
    ----------
    controller : Design, controller file path or ControllerFile
    plant : {'sim', 'physics', 'physics:actuation_ms=X'}
        The ARX models of ``model`` (default: the model the controller was designed on), or the
        physical simulator with ``preset`` (and the actuation timing, ms).
    reference : str
        A reference spec (``step:10``, ``square:8:2``, ``file:ref.csv`` …).
    duration_s : float
    """
    from cartctl.plants.factory import SIMULATED, plant_kind

    if plant_kind(plant) not in SIMULATED:
        raise InputError(f"simulate runs on 'sim' or 'physics[:actuation_ms=X]', not '{plant}'")
    if isinstance(controller, Design):
        file = replace(controller.controller_file(), path=None)
    elif isinstance(controller, ControllerFile):
        file = controller
    else:
        file = load_controller(controller)
    built = build_controllers(file)
    the_plant, _ = make_plant(plant, model_path=model or file.model_path, preset=preset,
                              noise_std_rad_s=noise_std_rad_s, seed=seed)  # fmt: skip
    period_s = the_plant.period_s
    n = max(1, round(float(duration_s) / period_s))
    refs = {m: ReferenceSchedule(reference, n, period_s, m) for m in MOTORS}
    columns, state = run_in_memory(the_plant, built, refs, period_s=period_s,
                                   voltage_limit_v=file.voltage_limit_v)  # fmt: skip
    return SimulationResult(columns, trace_metrics(columns, period_s), state.failure)
