"""``cartctl tune --robust``: every design scored on the nominal model, on plants drawn from the
model's uncertainty, and on the physics preset.

Per grid setting (:func:`evaluate_robust_chunk`, in the worker processes of
:func:`cartctl.tune.engine.run_grid`):

1. the design of each motor, as plain ``tune`` makes it (:func:`cartctl.design.make.design_motor`);
2. **nominal**: the real loop (``run_in_memory``) on the model, as plain ``tune`` scores it: these
   are the row's usual figures;
3. **sampled plants**: the same controllers against the nominal model and the N plants of
   :mod:`cartctl.tune.uncertainty` at once (:func:`cartctl.tune.batch.simulate_batch`), measured
   per plant by :func:`step_metrics` (the run summary's definitions, vectorised);
4. **physics**: the real loop on ``make_plant('physics', preset)`` (with ``--extra-delay`` ticks of
   delay), the preset as it is (its calibrated actuation timing): reported beside the rest, the
   check that a design chosen on the model's uncertainty also does well on a plant it was not
   chosen on;
5. **actuation timing** (``--actuation-ms``, default 3 and 10 ms: the presets' calibrated timing
   and microOS's documented order, the next tick's ``io()``): the real loop on
   ``make_plant('physics:actuation_ms=X', preset)`` at each listed X. When a command lands after
   its tick is a property of the cart that the ARX plants cannot express (their delay is whole
   ticks), so these runs are further plants of the uncertainty: they enter the worst case and the
   choice.

Per plant, each metric is the worse of motors a and b. Over the plants: the **worst case** is the
maximum over the nominal model, the N sampled plants and the physics runs at each actuation
timing (a plant on which the loop never settles, or runs away, or a physics run that fails, makes
worst-case settling infinite; JSON ``null``, with the counts beside it); ``worst_sampled`` is the
same over the nominal model and the sampled plants alone (the worst case without
``--actuation-ms``); the **spread** is the 5th, 50th and 95th percentile over the N sampled
plants, each the value of a sampled plant (numpy's ``inverted_cdf``: no interpolation, so
infinities stay meaningful).

The **robust Pareto front** is over (nominal settling time, worst-case overshoot), both to be
minimised, among the feasible settings where both are finite. ``--choose best`` takes, among the
feasible settings that settle on every plant (nominal, sampled and physics at each actuation
timing), the one with the lowest worst-case overshoot, overshoots equal to 0.01 % (the table's
resolution) counting as equal, then the fastest nominal settling, then the lowest index. Without ``--robust`` the same rule runs on the
row's figures (:func:`choose_best_nominal`).
"""

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
from cartctl.reference import reference_signal
from cartctl.runtime.base import Controller
from cartctl.tune.batch import ArxBatch, BatchTrace, simulate_batch
from cartctl.tune.engine import TuneJob, evaluate_nominal, scoring_plant, simulate
from cartctl.tune.grid import TuneResult, worst_metrics
from cartctl.tune.uncertainty import PlantSample

FloatArray = NDArray[np.float64]

ROBUST_METRICS = ("overshoot_percent", "settling_time_s", "rms_error", "peak_voltage_v")
"""The figures reported per plant (%, s, rad/s, V), the worse of motors a and b."""

PERCENTILES = (5, 50, 95)
"""The spread: these percentiles over the sampled plants."""

_SUMMARY_KEYS = {"overshoot_percent": "overshoot_percent", "settling_time_s": "settling_time_s",
                 "rms_error": "rms_error", "peak_voltage_v": "max_abs_voltage"}  # fmt: skip


# -- metrics over many plants --------------------------------------------------------------------


def step_metrics(trace: BatchTrace, settling_floor: float) -> dict[str, FloatArray]:
    """Per plant, the run summary's figures of one motor (``sinks.summary.motor_metrics``).

    The first reference step from rest, from its first non-zero level until its next change:
    overshoot (% of the step), settling time from the onset in the band max(2 % of the step,
    ``settling_floor``) with the crossing interpolated linearly; over the whole trace, the RMS
    tracking error and the largest |voltage|. Where the summary has None: ``inf`` settling for a
    run that never settles, NaN for a figure that is undefined (no step in the reference, or a
    step within its own settling band). Rows that ran away get ``inf`` for overshoot, settling
    and RMS error.

    Returns
    -------
    dict of str to ndarray, shape (N,)
        ``overshoot_percent`` (%), ``settling_time_s`` (s), ``rms_error`` (rad/s),
        ``peak_voltage_v`` (V).
    """
    t, ref, y = trace.time_s, trace.reference, trace.speed
    n = y.shape[0]
    with np.errstate(all="ignore"):
        out = {
            "overshoot_percent": np.full(n, np.nan),
            "settling_time_s": np.full(n, np.nan),
            "rms_error": np.sqrt(np.mean((ref - y) ** 2, axis=1)),
            "peak_voltage_v": np.max(np.abs(trace.voltage), axis=1),
        }
    span = first_step(ref)
    if span is not None:
        start, end = span
        size = float(ref[start])
        half_width = settling_half_width(size, settling_floor)
        with np.errstate(all="ignore"):
            overshoot, settling = step_rows(t[start:end], y[:, start:end] / size,
                                            half_width / abs(size), float(t[start]))  # fmt: skip
        out["overshoot_percent"] = overshoot
        if half_width < abs(size):  # else the band reaches back to rest: nothing to settle
            out["settling_time_s"] = settling
    for key in ("overshoot_percent", "settling_time_s", "rms_error"):
        out[key] = np.where(trace.diverged, np.inf, out[key])
    return out


@dataclass(frozen=True)
class RobustScore:
    """One design over the plants: nominal, worst case, spread, the physics preset and the physics
    runs at each actuation timing.

    Attributes
    ----------
    figures : dict of str to dict
        Per metric of :data:`ROBUST_METRICS`: ``nominal`` (the real loop on the model: the row's
        usual figure), ``worst`` (maximum over the nominal and the sampled plants and the physics
        runs of ``actuation``; ``inf`` when a plant never settles or runs away, or a physics run
        fails), ``worst_sampled`` (the same over the nominal and the sampled plants alone) and
        ``p5``, ``p50``, ``p95`` over the sampled plants.
    plants : int
        Sampled plants (the nominal model not counted).
    unsettled : int
        Plants (nominal and sampled) on which a motor never enters the settling band for good.
    diverged : int
        Plants on which the loop ran away (speed beyond 10⁶ rad/s).
    physics : dict
        The worse of motors a and b on the physics preset (``overshoot_percent``,
        ``settling_time_s``, ``rms_error``, ``peak_voltage_v``), its ``motors`` entries as
        ``cartctl run --json`` gives them, and ``failure`` (None, or what stopped the run).
    actuation : tuple of dict
        The physics runs at each actuation timing, as ``physics`` with ``actuation_ms`` (ms after
        its tick that a command lands) and ``settled`` (both motors settled, the run did not fail).
    """

    figures: dict[str, dict[str, float | None]]
    plants: int
    unsettled: int
    diverged: int
    physics: dict[str, Any] = field(default_factory=dict)
    actuation: tuple[dict[str, Any], ...] = ()

    @property
    def actuation_unsettled(self) -> int:
        """Physics runs of ``actuation`` that did not settle or failed."""
        return sum(not entry["settled"] for entry in self.actuation)

    def value(self, metric: str, which: str) -> float:
        """A figure as a float: NaN where undefined (``worst`` may be ``inf``)."""
        v = self.figures[metric][which]
        return math.nan if v is None else float(v)

    @property
    def settles_everywhere(self) -> bool:
        """Every plant (nominal, sampled, physics at each actuation timing) settles; none ran away."""
        return math.isfinite(self.value("settling_time_s", "worst"))

    def to_dict(self) -> dict[str, Any]:
        """JSON form (infinities become ``null`` in ``--json``; the counts say why)."""
        return {"nominal": {k: self.figures[k]["nominal"] for k in ROBUST_METRICS},
                "worst": {k: self.figures[k]["worst"] for k in ROBUST_METRICS},
                "worst_sampled": {k: self.figures[k]["worst_sampled"] for k in ROBUST_METRICS},
                **{f"p{p}": {k: self.figures[k][f"p{p}"] for k in ROBUST_METRICS}
                   for p in PERCENTILES},
                "plants": self.plants, "plants_unsettled": self.unsettled,
                "plants_diverged": self.diverged, "settles_on_every_plant": self.settles_everywhere,
                "physics": self.physics, "actuation": list(self.actuation),
                "actuation_unsettled": self.actuation_unsettled}  # fmt: skip


def _worse_of_motors(per_motor: Sequence[dict[str, FloatArray]]) -> dict[str, FloatArray]:
    """Per plant and metric, the larger of the motors; NaN (undefined) wins, then inf."""
    out = {}
    for key in ROBUST_METRICS:
        stack = np.vstack([m[key] for m in per_motor])
        out[key] = np.where(np.isnan(stack).any(axis=0), np.nan, np.max(stack, axis=0))
    return out


def _timing_value(entry: dict[str, Any], key: str) -> float:
    """A physics run's figure for the worst case: ``inf`` for a failed or unsettled run's
    overshoot, settling and RMS error (as a sampled plant that ran away), NaN where undefined."""
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
    """Aggregate :func:`step_metrics` of the motors (row 0 the nominal model, then the samples)
    with the nominal figures of the real loop, the physics entry and the physics runs at each
    actuation timing, which enter the worst case (see :class:`RobustScore`)."""
    worse = _worse_of_motors(per_motor)
    unsettled_rows = np.isinf(worse["settling_time_s"]) & ~diverged
    figures: dict[str, dict[str, float | None]] = {}
    for key in ROBUST_METRICS:
        values = worse[key]
        row: dict[str, float | None] = {"nominal": nominal.get(key)}
        row["worst_sampled"] = None if np.isnan(values).any() else float(np.max(values))
        timed = [_timing_value(entry, key) for entry in actuation]
        everything = np.concatenate([values, timed])
        row["worst"] = None if np.isnan(everything).any() else float(np.max(everything))
        sampled = values[1:]
        for p in PERCENTILES:
            v = (math.nan if not sampled.size or np.isnan(sampled).any()
                 else float(np.percentile(sampled, p, method="inverted_cdf")))  # fmt: skip
            row[f"p{p}"] = None if math.isnan(v) else v
        figures[key] = row
    return RobustScore(figures, int(diverged.size - 1), int(np.count_nonzero(unsettled_rows)),
                       int(np.count_nonzero(diverged)), physics, tuple(actuation))  # fmt: skip


# -- the grid ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RobustJob:
    """A chunk of settings for the workers, with the plants (picklable).

    Attributes
    ----------
    tune : TuneJob
        Model, method, reference, duration, extra delay and physics preset, as plain ``tune``'s
        job (its ``plant`` is 'sim': the nominal model; its own ``items`` unused).
    sample : PlantSample
        The sampled plants.
    items : tuple of (int, dict)
        The settings: (1-based grid index, axis values).
    actuation_ms : tuple of float
        The actuation timings (ms after its tick that a command lands, each in (0, 10]) at which
        every setting also runs on the physics preset; these runs enter the worst case. Empty:
        none (the physics preset is then only reported).
    """

    tune: TuneJob
    sample: PlantSample
    items: tuple[tuple[int, dict[str, float]], ...]
    actuation_ms: tuple[float, ...] = ()


@dataclass(frozen=True)
class RobustRow:
    """A setting's plain ``tune`` result (nominal) with its robust score and front mark."""

    result: TuneResult
    score: RobustScore | None = None
    pareto: bool = False

    @property
    def index(self) -> int:
        """The setting's 1-based grid index."""
        return self.result.index

    def to_dict(self) -> dict[str, Any]:
        """The plain row (its keys unchanged) with ``robust``: :meth:`RobustScore.to_dict` and
        ``pareto`` (the robust front), or None when infeasible."""
        row = self.result.to_dict()
        row["robust"] = (None if self.score is None
                         else {**self.score.to_dict(), "pareto": self.pareto})  # fmt: skip
        return row


def _batch_plants(models: ModelFile, sample: PlantSample, motor: str, extra: int) -> ArxBatch:
    nominal = models.motor(motor).with_extra_delay(extra)
    s = sample.motors[motor]
    return ArxBatch.from_arrays(np.vstack([np.asarray(nominal.ar, float)[None, :], s.ar]),
                                np.vstack([np.asarray(nominal.b, float)[None, :], s.b]),
                                np.concatenate([[nominal.nk], s.nk]),
                                period_s=models.period_s)  # fmt: skip


def physics_spec(actuation_ms: float | None = None) -> str:
    """The plant name of the physics simulator, at ``actuation_ms`` (None: the preset's own)."""
    return "physics" if actuation_ms is None else f"physics:actuation_ms={actuation_ms:g}"


def _physics(job: TuneJob, controllers: dict[str, Controller], limit_v: float,
             actuation_ms: float | None = None) -> dict[str, Any]:  # fmt: skip
    plant = scoring_plant(replace(job, plant=physics_spec(actuation_ms)))
    n = max(1, round(job.duration_s / plant.period_s))
    refs = {m: reference_signal(job.reference, n, plant.period_s, m) for m in ("a", "b")}
    summary, failure = simulate(plant, controllers, refs, period_s=plant.period_s,
                                voltage_limit_v=limit_v)  # fmt: skip
    worst = (
        worst_metrics(summary["motors"]) if not failure else dict.fromkeys(_SUMMARY_KEYS.values())
    )
    entry = {"preset": job.preset, **{k: worst[v] for k, v in _SUMMARY_KEYS.items()},
             "failure": failure, "motors": summary["motors"]}  # fmt: skip
    if actuation_ms is None:
        return entry
    settled = not failure and all(m.get("settling_time_s") is not None
                                  for m in summary["motors"].values())  # fmt: skip
    return {"actuation_ms": actuation_ms, **entry, "settled": settled}


def evaluate_robust(job: RobustJob, models: ModelFile, index: int,
                    settings: dict[str, float]) -> RobustRow:  # fmt: skip
    """One setting: designed, run on the nominal model, the sampled plants, the physics preset and
    the physics preset at each of ``job.actuation_ms``."""
    tj = job.tune
    nominal_run = evaluate_nominal(tj, models, index, settings)
    result = nominal_run.result
    if not result.feasible:
        return RobustRow(result)
    controllers, refs, limit_v = (nominal_run.controllers, nominal_run.references,
                                  nominal_run.voltage_limit_v)  # fmt: skip
    floor = encoder_quantum_rad_s(nominal_run.period_s)
    per_motor, diverged = [], np.zeros(job.sample.size + 1, dtype=bool)
    for m in ("a", "b"):
        trace = simulate_batch(controllers[m],
                               _batch_plants(models, job.sample, m, tj.extra_delay_ticks),
                               refs[m], voltage_limit_v=limit_v)  # fmt: skip
        per_motor.append(step_metrics(trace, floor))
        diverged |= trace.diverged
    nominal = {k: result.worst[v] for k, v in _SUMMARY_KEYS.items()}
    physics = _physics(tj, controllers, limit_v)
    actuation = [_physics(tj, controllers, limit_v, ms) for ms in job.actuation_ms]
    return RobustRow(result, score_plants(per_motor, diverged, nominal, physics, actuation))


def evaluate_robust_chunk(job: RobustJob) -> list[RobustRow]:
    """Every setting of a chunk (the worker function of the process pool)."""
    models = load_models(job.tune.model)
    return [evaluate_robust(job, models, i, s) for i, s in job.items]
