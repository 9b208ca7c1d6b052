"""Running a tuning grid: each setting designed per motor by the design command's own path
(:func:`~cartctl.design.make.design_motor`), run in memory in the loop of ``cartctl run --fast`` on
the loop it is designed for (:func:`scoring_plant`) and summarised by ``trace_metrics``; settings
are spread over worker processes in chunks, and a refused design is a result, not an error."""

from __future__ import annotations

import math
import shlex
from collections import deque
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.data.modelfile import ModelFile, load_models
from cartctl.design.make import design_motor
from cartctl.errors import CartctlError
from cartctl.model import check_extra_delay_ticks
from cartctl.plants.base import Measurement, Plant
from cartctl.plants.factory import make_plant
from cartctl.reference import reference_signal
from cartctl.runtime.base import Controller
from cartctl.runtime.loop import run_in_memory
from cartctl.runtime.realtime import one_blas_thread
from cartctl.sinks.summary import trace_metrics
from cartctl.tune.grid import RUN_FAILED, TuneResult, design_request, request_axes


@dataclass(frozen=True)
class TuneJob:
    """A chunk of settings with what they share (picklable, for a worker process). ``model`` is
    designed on and is the sim plant's model; ``plant``/``preset`` as for ``make_plant``;
    ``reference`` a spec of both motors (rad/s); ``duration_s`` per setting; ``extra_delay_ticks``
    the loop delay beyond the model's, which the designs allow for and the scoring plant has;
    ``items`` the (1-based grid index, axis values); ``design`` request fields every setting shares
    (``process_noise_std_v`` …)."""

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
    """A plant whose commands arrive ``ticks`` ticks late (zero volts at first): a PC-side loop's
    delay."""

    def __init__(self, plant: Plant, ticks: int) -> None:
        self.plant = plant
        self.ticks = check_extra_delay_ticks(ticks)
        self.period_s = plant.period_s

    def reset(self) -> Measurement:
        self._queue = deque([(0.0, 0.0)] * self.ticks)
        return self.plant.reset()

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        self._queue.append((voltage_a_v, voltage_b_v))  # sent ``ticks`` ticks from now
        return self.plant.step(*self._queue.popleft())

    def close(self) -> None:
        self.plant.close()


def scoring_plant(job: TuneJob) -> Plant:
    """The plant a setting of ``job`` is scored on: ``job.plant`` with its commands
    ``job.extra_delay_ticks`` ticks late (for the sim plant the same as models with nk + d, as
    ``design``'s simulated step)."""
    plant, _ = make_plant(job.plant, model_path=job.model, preset=job.preset)
    return DelayedPlant(plant, job.extra_delay_ticks) if job.extra_delay_ticks else plant


def simulate(
    plant: Plant,
    controllers: Mapping[str, Controller],
    references: Mapping[str, Any],
    limit_v: float,
) -> tuple[dict[str, Any], str | None]:
    """The loop of ``cartctl run --fast`` in memory at the plant's period, commands clamped to
    ±``limit_v``: (``trace_metrics`` summary, failure)."""
    period_s = plant.period_s
    columns, state = run_in_memory(
        plant, controllers, references, period_s=period_s, voltage_limit_v=limit_v
    )
    return trace_metrics(columns, period_s), state.failure


@dataclass(frozen=True)
class Nominal:
    """A setting scored on its nominal plant, with what it ran with (for more plants)."""

    result: TuneResult
    controllers: dict[str, Controller] = field(default_factory=dict)
    references: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    voltage_limit_v: float = 0.0


def evaluate_nominal(
    job: TuneJob, models: ModelFile, index: int, settings: dict[str, float]
) -> Nominal:
    """Design one setting per motor (a refused design is the result's reason) and run it on the
    scoring plant."""
    request = design_request(job.method, settings, job.extra_delay_ticks, dict(job.design))
    controllers: dict[str, Controller] = {}
    for m in ("a", "b"):
        try:
            controllers[m] = design_motor(request, models.motor(m)).controller
        except (CartctlError, np.linalg.LinAlgError) as exc:
            return Nominal(TuneResult(index, settings, False, f"motor {m}: {exc}"))
    limit_v = request.voltage_limit_v
    plant = scoring_plant(job)
    n = max(1, round(job.duration_s / plant.period_s))
    refs = {m: reference_signal(job.reference, n, plant.period_s, m) for m in ("a", "b")}
    summary, failure = simulate(plant, controllers, refs, limit_v)
    if failure:
        return Nominal(TuneResult(index, settings, False, RUN_FAILED + failure))
    result = TuneResult(index, settings, True, motors=summary["motors"])
    return Nominal(result, controllers, refs, limit_v)


def save_setting(method: str, settings: Mapping[str, float], model_path: str | Path,
                 out: str | Path, extra_delay_ticks: int = 0,
                 fixed: Mapping[str, Any] | None = None) -> str:  # fmt: skip
    """Write a setting's controller file to ``out`` as ``cartctl design --out`` would (with the
    loop's refined analysis); returns the design command the file records."""
    from cartctl.design.controllerfile import save_controller
    from cartctl.design.make import controller_file, design_models

    request = design_request(method, settings, extra_delay_ticks, fixed)
    options = request.to_argv(str(model_path), always=request_axes(method))
    models = load_models(model_path)
    designs = design_models(request, models, ("a", "b"))
    command = "cartctl " + shlex.join(["design", *options, "--out", str(out)])
    save_controller(controller_file(designs, model_path, command=command,
                                    period_s=models.period_s), out)  # fmt: skip
    return command


def evaluate_chunk(job: TuneJob) -> list[TuneResult]:  # the process pool's worker function
    models = load_models(job.model)
    return [evaluate_nominal(job, models, i, s).result for i, s in job.items]


def run_grid(
    job: Any,
    jobs: int,
    progress: Callable[[int], None] | None = None,
    evaluate: Callable[[Any], list[Any]] = evaluate_chunk,
) -> list[Any]:
    """Every setting of ``job`` (a dataclass with ``items``) in grid order, on ``jobs`` processes.
    With 1 process everything runs here; otherwise the first setting runs here (its lazy imports are
    paid before the workers fork) and the rest in chunks of about a quarter of a worker's share.
    ``progress`` gets the count done so far; ``evaluate`` maps a chunk to rows with their grid
    ``index`` (default :func:`evaluate_chunk`)."""
    items, done = job.items, progress or (lambda count: None)
    results: list[Any] = []
    for item in items if jobs == 1 else items[:1]:
        results += evaluate(replace(job, items=(item,)))
        done(len(results))
    rest = items[1:] if jobs > 1 else ()
    if rest:
        # a feasible setting's design imports python-control (and matplotlib with it); a refused
        # first setting does not, so it is imported here once, not again in each worker
        import control  # noqa: F401

        size = max(1, math.ceil(len(rest) / (4 * jobs)))
        chunks = [replace(job, items=rest[i : i + size]) for i in range(0, len(rest), size)]
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(chunks)), initializer=one_blas_thread)
        try:
            for future in as_completed([pool.submit(evaluate, c) for c in chunks]):
                results += future.result()
                done(len(results))
        finally:
            pool.shutdown(cancel_futures=True)
    return sorted(results, key=lambda r: r.index)
