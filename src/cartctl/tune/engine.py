"""Running a tuning grid: each setting designed, then run in the loop of ``cartctl run --fast``.

The execution part of ``cartctl tune`` (:mod:`cartctl.cli.commands.tune`); the grid, the result rows
and the Pareto front are in :mod:`cartctl.tune.grid`. A setting is designed per motor by
:func:`cartctl.design.make.design_motor` (the design command's own path, from the setting's
:class:`~cartctl.design.request.DesignRequest`), run by
:func:`simulate` (ControlLoop, BackToBackExecutor, SimulatedClock and a MemorySink: the loop of
``run --fast`` without files) and summarised by the run summary's ``trace_metrics`` (settling in
the band of the design's settling bound, max(2 %, one encoder count per tick)). The settings are
spread over worker processes in chunks; a refused design is a result, not an error.

Every setting is scored on the loop it is designed for (:func:`scoring_plant`): with
``--extra-delay d`` the plant carries d more ticks of delay, the sim plant being the model with
nk + d as in ``cartctl design``'s simulated step.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from cartctl.data.modelfile import ModelFile, load_models
from cartctl.design.make import design_motor
from cartctl.errors import CartctlError
from cartctl.model import check_extra_delay_ticks
from cartctl.plants.base import Measurement, Plant
from cartctl.plants.factory import make_plant
from cartctl.plants.sim import ArxPlant
from cartctl.reference import reference_signal
from cartctl.runtime.base import Controller
from cartctl.runtime.fast import run_in_memory
from cartctl.sinks.summary import trace_metrics
from cartctl.tune.grid import TuneResult, design_request


@dataclass(frozen=True)
class TuneJob:
    """A chunk of settings, with what every setting shares (picklable, for a worker process).

    Attributes
    ----------
    model : str
        Model file designed on, and the sim plant's model.
    method : {'pi', 'poles'}
    plant, preset : str
        Plant name ('sim' or 'physics') and physics preset, as for ``make_plant``.
    reference : str
        Reference spec of both motors (rad/s; see :mod:`cartctl.reference`).
    duration_s : float
        Run time per setting (s).
    extra_delay_ticks : int
        Loop delay beyond the model's (ticks): the designs allow for it and the simulated loop has
        it (:func:`scoring_plant`).
    items : tuple of (int, dict)
        The settings: (1-based grid index, axis values).
    design : tuple of (str, float)
        Design request fields every setting shares (``process_noise_std_v``,
        ``bias_drift_std_v``), beside the design command's defaults; empty: the defaults.
    """

    model: str
    method: str
    plant: str
    preset: str
    reference: str
    duration_s: float
    extra_delay_ticks: int
    items: tuple[tuple[int, dict[str, float]], ...]
    design: tuple[tuple[str, float], ...] = ()


class DelayedPlant:
    """A plant whose commands arrive ``ticks`` ticks late (a PC-side loop's extra delay).

    Commands wait in a queue, zero volts at first; the inner plant saturates them as usual.

    Parameters
    ----------
    plant : Plant
        The plant delayed (it keeps its own delay).
    ticks : int
        Extra ticks of delay (>= 0).
    """

    def __init__(self, plant: Plant, ticks: int) -> None:
        self.plant = plant
        self.ticks = check_extra_delay_ticks(ticks)
        self.period_s = plant.period_s
        self._queue: deque[tuple[float, float]] = deque()

    def reset(self) -> Measurement:
        """Inner plant at rest, the queue back to zero volts; the tick-0 measurement."""
        self._queue = deque([(0.0, 0.0)] * self.ticks)
        return self.plant.reset()

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        """Queue this tick's command, send the one ``ticks`` ticks old, measure tick k + 1."""
        self._queue.append((voltage_a_v, voltage_b_v))
        return self.plant.step(*self._queue.popleft())

    def close(self) -> None:
        """Close the inner plant."""
        self.plant.close()


def scoring_plant(job: TuneJob) -> Plant:
    """The plant a setting of ``job`` is scored on: the loop its design is for.

    ``make_plant(job.plant, …)`` with ``job.extra_delay_ticks`` more ticks of delay: for the sim
    plant, the ARX models with input delay nk + d (the plant of ``cartctl design``'s simulated
    step with ``--extra-delay d``); for the physics plant, its commands delayed by d ticks.
    """
    plant, _ = make_plant(job.plant, model_path=job.model, preset=job.preset)
    d = job.extra_delay_ticks
    if d == 0:
        return plant
    if isinstance(plant, ArxPlant):
        a, b = (m.with_extra_delay(d) for m in plant.models)
        return ArxPlant(a, b, noise_std_rad_s=plant.noise_std_rad_s, seed=plant.seed,
                        voltage_limit_v=plant.voltage_limit_v)  # fmt: skip
    return DelayedPlant(plant, d)


def simulate(
    plant: Plant,
    controllers: Mapping[str, Controller],
    references: Mapping[str, NDArray[np.float64]],
    *,
    period_s: float,
    voltage_limit_v: float,
) -> tuple[dict[str, Any], str | None]:
    """The loop of ``cartctl run --fast`` kept in memory: (``trace_metrics`` summary, failure)."""
    columns, state = run_in_memory(plant, controllers, references, period_s=period_s,
                                   voltage_limit_v=voltage_limit_v)  # fmt: skip
    return trace_metrics(columns, period_s), state.failure


def design_setting(
    job: TuneJob, models: ModelFile, settings: dict[str, float]
) -> tuple[dict[str, Controller], float] | str:
    """One grid setting's runtime controller per motor and its voltage limit (V), or why a motor's
    design was refused."""
    request = design_request(job.method, settings, job.extra_delay_ticks, dict(job.design))
    controllers: dict[str, Controller] = {}
    for m in ("a", "b"):
        try:
            controllers[m] = design_motor(request, models.motor(m)).controller
        except (CartctlError, np.linalg.LinAlgError) as exc:
            return f"motor {m}: {exc}"
    return controllers, request.voltage_limit_v


@dataclass(frozen=True)
class Nominal:
    """A setting scored on its nominal plant, with what it was run with (for more plants)."""

    result: TuneResult
    controllers: dict[str, Controller] = field(default_factory=dict)
    references: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    voltage_limit_v: float = 0.0
    period_s: float = 0.0


def evaluate_nominal(
    job: TuneJob, models: ModelFile, index: int, settings: dict[str, float]
) -> Nominal:
    """Design one setting and run it on the scoring plant (:func:`scoring_plant`)."""
    designed = design_setting(job, models, settings)
    if isinstance(designed, str):
        return Nominal(TuneResult(index, settings, False, designed))
    controllers, limit_v = designed
    plant = scoring_plant(job)
    n = max(1, round(job.duration_s / plant.period_s))
    refs = {m: reference_signal(job.reference, n, plant.period_s, m) for m in ("a", "b")}
    summary, failure = simulate(plant, controllers, refs, period_s=plant.period_s,
                                voltage_limit_v=limit_v)  # fmt: skip
    if failure:
        return Nominal(TuneResult(index, settings, False, f"the run failed: {failure}"))
    result = TuneResult(index, settings, True, motors=summary["motors"])
    return Nominal(result, controllers, refs, limit_v, plant.period_s)


def _evaluate(job: TuneJob, models: ModelFile, index: int,
              settings: dict[str, float]) -> TuneResult:  # fmt: skip
    return evaluate_nominal(job, models, index, settings).result


def evaluate_chunk(job: TuneJob) -> list[TuneResult]:
    """Design and run every setting of a chunk (the worker function of the process pool)."""
    models = load_models(job.model)
    return [_evaluate(job, models, i, s) for i, s in job.items]


def one_blas_thread() -> None:
    """Worker initializer: one BLAS thread in this process (threadpoolctl).

    A forked worker keeps the parent's BLAS thread pool (as many threads as cores); two workers
    on two cores then compete with each other's BLAS threads and the grid runs no faster than in
    one process.
    """
    threadpool_limits(limits=1, user_api="blas")


class GridJob(Protocol):
    """A job :func:`run_grid` can split: a dataclass (frozen or not) with the settings as ``items``."""

    __dataclass_fields__: ClassVar[dict[str, Any]]

    @property
    def items(self) -> tuple[tuple[int, dict[str, float]], ...]:
        """The settings: (1-based grid index, axis values)."""
        ...


class GridRow(Protocol):
    """A result of one setting: :func:`run_grid` puts them back in grid order by ``index``."""

    @property
    def index(self) -> int:
        """The setting's 1-based grid index."""
        ...


Job = TypeVar("Job", bound=GridJob)
Row = TypeVar("Row", bound=GridRow)


def run_grid(
    job: Job,
    jobs: int,
    progress: Callable[[int], None] | None = None,
    evaluate: Callable[[Job], list[Row]] = evaluate_chunk,  # type: ignore[assignment]
) -> list[Row]:
    """Every setting of ``job``, in grid order, on ``jobs`` processes.

    Parameters
    ----------
    job : TuneJob or another dataclass with ``items``
        All the settings.
    jobs : int
        Processes (>= 1). With 1 everything runs in this process. Otherwise the first setting
        runs here (its lazy imports and first-call costs are then paid before the workers fork,
        not once per worker) and the rest in chunks of about a quarter of a worker's share.
    progress : callable, optional
        Called with the number of settings done so far as results arrive.
    evaluate : callable
        The worker function: a chunk (``job`` with some of its items) to its rows, each with an
        ``index`` (default :func:`evaluate_chunk`; ``--robust`` passes its own).
    """
    items = job.items
    results: list[Row] = []
    for item in items if jobs == 1 else items[:1]:
        results += evaluate(replace(job, items=(item,)))
        if progress is not None:
            progress(len(results))
    rest = items[1:] if jobs > 1 else ()
    if rest:
        size = max(1, math.ceil(len(rest) / (4 * jobs)))
        chunks = [replace(job, items=rest[i : i + size]) for i in range(0, len(rest), size)]
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(chunks)), initializer=one_blas_thread)
        try:
            for future in as_completed([pool.submit(evaluate, c) for c in chunks]):
                results += future.result()
                if progress is not None:
                    progress(len(results))
        finally:
            pool.shutdown(cancel_futures=True)
    return sorted(results, key=lambda r: r.index)
