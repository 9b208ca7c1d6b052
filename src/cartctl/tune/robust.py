"""``cartctl tune --robust``: each design scored on the nominal model, on plants drawn from its
uncertainty (:mod:`cartctl.tune.batch`), on the physics preset (reported only) and on the physics
preset at each ``--actuation-ms``; per plant each metric is the worse of motors a and b. The worst
case and the spread: docs/tuning.md (percentiles ``inverted_cdf``: each a plant's value)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import encoder_quantum_rad_s
from cartctl.data.modelfile import ModelFile, load_models
from cartctl.measures.stepinfo import first_step, settling_half_width, step_rows
from cartctl.plants.base import Plant
from cartctl.plants.sim import ArxPlant
from cartctl.reference import reference_signal
from cartctl.tune.batch import ArxBatch, BatchTrace, PlantSample, later_command, simulate_batch
from cartctl.tune.engine import Nominal, TuneJob, evaluate_nominal, scoring_plant, simulate
from cartctl.tune.grid import METRICS, TuneResult, worst_metrics

FloatArray = NDArray[np.float64]

# the robust metrics (%, s, rad/s, V), each with its key in the run summary (grid.METRICS)
ROBUST_METRICS = ("overshoot_percent", "settling_time_s", "rms_error", "peak_voltage_v")
SUMMARY_KEYS = dict(zip(ROBUST_METRICS, METRICS, strict=True))
PERCENTILES = (5, 50, 95)  # the spread over the sampled plants


def step_metrics(trace: BatchTrace, settling_floor: float) -> dict[str, FloatArray]:
    """Per plant, the run summary's figures of one motor (``sinks.summary.motor_metrics``). On the
    first reference step from rest: overshoot (%) and settling time (s) in the band max(2 % of the
    step, ``settling_floor``); over the whole trace the RMS error (rad/s) and the peak |voltage|
    (V). Where the summary has None: ``inf`` settling for a run that never settles, NaN for an
    undefined figure; rows that ran away get ``inf`` for all but the voltage."""
    t, ref, y = trace.time_s, trace.reference, trace.speed
    overshoot = settling = np.full(y.shape[0], np.nan)
    span = first_step(ref)
    with np.errstate(all="ignore"):
        rms = np.sqrt(np.mean((ref - y) ** 2, axis=1))
        if span is not None:
            start, end = span
            size = float(ref[start])
            half_width = settling_half_width(size, settling_floor)
            overshoot, settled = step_rows(t[start:end], y[:, start:end] / size,
                                           half_width / abs(size), float(t[start]))  # fmt: skip
            if half_width < abs(size):  # else the band reaches back to rest: nothing to settle
                settling = settled
    out = {"overshoot_percent": overshoot, "settling_time_s": settling, "rms_error": rms}
    out = {key: np.where(trace.diverged, np.inf, v) for key, v in out.items()}
    return out | {"peak_voltage_v": np.max(np.abs(trace.voltage), axis=1)}


@dataclass(frozen=True)
class RobustScore:
    """One design over the plants. ``figures[metric]`` holds ``nominal`` (the real loop on the
    model), ``worst``, ``worst_sampled``, ``p5``, ``p50`` and ``p95`` (module docstring). ``plants``
    counts the sampled plants, ``unsettled`` the plants (nominal and sampled) on which a motor never
    settles, ``diverged`` those that ran away (speed beyond 10⁶ rad/s). ``physics`` is the physics
    preset's entry and ``actuation`` one per actuation timing (:func:`loop_entry`, with
    ``actuation_ms``)."""

    figures: dict[str, dict[str, float | None]]
    plants: int
    unsettled: int
    diverged: int
    physics: dict[str, Any] = field(default_factory=dict)
    actuation: tuple[dict[str, Any], ...] = ()

    def value(self, metric: str, which: str) -> float:
        """A figure as a float: NaN where undefined (``worst`` may be ``inf``)."""
        v = self.figures[metric][which]
        return math.nan if v is None else float(v)

    @property
    def settles_everywhere(self) -> bool:
        return math.isfinite(self.value("settling_time_s", "worst"))

    @property
    def front_axes(self) -> tuple[float, float]:
        """The robust front's (nominal settling s, worst-case overshoot %), NaN where undefined."""
        return self.value("settling_time_s", "nominal"), self.value("overshoot_percent", "worst")

    def to_dict(self) -> dict[str, Any]:
        """JSON form (infinities become ``null`` in ``--json``; the counts say why)."""
        which = ("nominal", "worst", "worst_sampled", *(f"p{p}" for p in PERCENTILES))
        return {**{w: {k: self.figures[k][w] for k in ROBUST_METRICS} for w in which},
                "plants": self.plants, "plants_unsettled": self.unsettled,
                "plants_diverged": self.diverged, "settles_on_every_plant": self.settles_everywhere,
                "physics": self.physics, "actuation": list(self.actuation),
                "actuation_unsettled": sum(not e["settled"] for e in self.actuation)}  # fmt: skip


def _timing_value(entry: dict[str, Any], key: str) -> float:
    """An actuation run's figure for the worst case: ``inf`` for a failed or unsettled run (as a
    sampled plant that ran away), NaN where undefined."""
    value = entry.get(key)
    if entry.get("failure") and key != "peak_voltage_v":
        return math.inf
    if value is None:
        return math.inf if key == "settling_time_s" else math.nan
    return float(value)


def score_plants(
    per_motor: Sequence[dict[str, FloatArray]],
    diverged: NDArray[np.bool_],
    nominal: dict[str, float | None],
    physics: dict[str, Any],
    actuation: Sequence[dict[str, Any]] = (),
) -> RobustScore:
    """Aggregate :func:`step_metrics` of the motors (row 0 the nominal model) with the nominal
    figures, the physics entry and the actuation runs (:class:`RobustScore`)."""
    # per plant and metric the worse motor: NaN (undefined) wins, then inf
    worse = {key: np.max([m[key] for m in per_motor], axis=0) for key in ROBUST_METRICS}
    unsettled_rows = np.isinf(worse["settling_time_s"]) & ~diverged
    figures: dict[str, dict[str, float | None]] = {}
    for key in ROBUST_METRICS:
        values, sampled = worse[key], worse[key][1:]
        everything = np.concatenate([values, [_timing_value(entry, key) for entry in actuation]])
        row: dict[str, float | None] = {"nominal": nominal.get(key)}
        for which, v in (("worst_sampled", values), ("worst", everything)):
            row[which] = None if np.isnan(v).any() else float(np.max(v))
        spread = sampled.size > 0 and not np.isnan(sampled).any()
        for p in PERCENTILES:
            row[f"p{p}"] = (
                float(np.percentile(sampled, p, method="inverted_cdf")) if spread else None
            )
        figures[key] = row
    plants, unsettled = int(diverged.size - 1), int(np.count_nonzero(unsettled_rows))
    return RobustScore(
        figures, plants, unsettled, int(np.count_nonzero(diverged)), physics, tuple(actuation)
    )


@dataclass(frozen=True, kw_only=True)
class RobustJob(TuneJob):
    """Plain ``tune``'s job (its ``plant`` 'sim') with the sampled plants and the actuation timings
    (ms, each in (0, 10]) at which every setting also runs on the physics preset, or (commission)
    the fractions of a tick by which the model's commands land later."""

    sample: PlantSample
    actuation_ms: tuple[float, ...] = ()
    later_fractions: tuple[float, ...] = ()


@dataclass(frozen=True)
class RobustRow:
    """A setting's plain ``tune`` result with its robust score and robust-front mark."""

    result: TuneResult
    score: RobustScore | None = None
    pareto: bool = False

    @property
    def index(self) -> int:
        return self.result.index

    def to_dict(self) -> dict[str, Any]:
        """The plain row with ``robust``: the score's JSON and ``pareto`` (None: infeasible)."""
        score = None if self.score is None else {**self.score.to_dict(), "pareto": self.pareto}
        return {**self.result.to_dict(), "robust": score}


def loop_entry(plant: Plant, nominal: Nominal, references: dict[str, FloatArray]) -> dict[str, Any]:
    """A setting's controllers in the real loop on ``plant``: the worse of motors a and b per
    :data:`ROBUST_METRICS`, ``failure``, the ``motors`` entries and ``settled`` (both motors
    settled, the run did not fail)."""
    summary, failure = simulate(plant, nominal.controllers, references, nominal.voltage_limit_v)
    motors = summary["motors"]
    worst = worst_metrics({} if failure else motors)  # all None for a failed run
    entry = {k: worst[v] for k, v in SUMMARY_KEYS.items()}
    settled = entry["settling_time_s"] is not None
    return entry | {"failure": failure, "motors": motors, "settled": settled}


def _physics(job: TuneJob, nominal: Nominal, actuation_ms: float | None = None) -> dict[str, Any]:
    """The physics preset's entry, at ``actuation_ms`` (None: the preset's own timing)."""
    spec = "physics" if actuation_ms is None else f"physics:actuation_ms={actuation_ms:g}"
    plant = scoring_plant(replace(job, plant=spec))
    n = max(1, round(job.duration_s / plant.period_s))
    refs = {m: reference_signal(job.reference, n, plant.period_s, m) for m in ("a", "b")}
    entry = {"preset": job.preset, **loop_entry(plant, nominal, refs)}
    if actuation_ms is None:
        del entry["settled"]
        return entry
    return {"actuation_ms": actuation_ms, **entry}


def sampled_metrics(
    nominal: Nominal, models: ModelFile, sample: PlantSample, extra_delay_ticks: int
) -> tuple[list[dict[str, FloatArray]], NDArray[np.bool_]]:
    """:func:`step_metrics` per motor of a setting on the nominal model (row 0) and the sampled
    plants (batch loop), and which rows ran away."""
    floor = encoder_quantum_rad_s(models.period_s)  # the sim plant's period
    per_motor, diverged = [], np.zeros(sample.size + 1, dtype=bool)
    for m in ("a", "b"):
        model, s = models.motor(m).with_extra_delay(extra_delay_ticks), sample.motors[m]
        rows = [model.ar, *s.ar], [model.b, *s.b], [model.nk, *s.nk]  # row 0: the model
        plants = ArxBatch.from_arrays(*rows, period_s=models.period_s)
        trace = simulate_batch(nominal.controllers[m], plants, nominal.references[m],
                               voltage_limit_v=nominal.voltage_limit_v)  # fmt: skip
        per_motor.append(step_metrics(trace, floor))
        diverged |= trace.diverged
    return per_motor, diverged


def evaluate_robust(job: RobustJob, models: ModelFile, index: int,
                    settings: dict[str, float]) -> RobustRow:  # fmt: skip
    """One setting on the nominal model, the sampled plants, the physics preset and the physics
    preset at each of ``job.actuation_ms``."""
    nominal = evaluate_nominal(job, models, index, settings)
    if not nominal.result.feasible:
        return RobustRow(nominal.result)
    per_motor, diverged = sampled_metrics(nominal, models, job.sample, job.extra_delay_ticks)
    figures = {k: nominal.result.worst[v] for k, v in SUMMARY_KEYS.items()}
    if job.later_fractions:  # commissioning: the model with later commands, not the physics
        physics: dict[str, Any] = {}
        actuation: list[dict[str, Any]] = []
        for f in job.later_fractions:
            plant = ArxPlant(*(later_command(models.motor(m), f) for m in "ab"))
            entry = loop_entry(plant, nominal, nominal.references)
            actuation.append({"later_ms": round(f * models.period_s * 1e3, 3), **entry})
    else:
        physics = _physics(job, nominal)
        actuation = [_physics(job, nominal, ms) for ms in job.actuation_ms]
    return RobustRow(nominal.result, score_plants(per_motor, diverged, figures, physics, actuation))


def evaluate_robust_chunk(job: RobustJob) -> list[RobustRow]:  # the process pool's worker
    models = load_models(job.model)
    return [evaluate_robust(job, models, i, s) for i, s in job.items]
