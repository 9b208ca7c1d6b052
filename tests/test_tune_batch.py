"""The loop vectorised over plants (``cartctl.tune.batch``) against the real loop, plant by plant.

The expectation is always the runtime's own loop: ``run_in_memory`` with the runtime controller
(``design_motor``'s, or one built by hand) and an ``ArxPlant`` per plant; the batch must give the
same trace (to 1e-9 rad/s and V), with saturation, every anti-windup mode and both estimators. Its
metrics must equal the run summary's (``sinks.summary.motor_metrics``) on each trace.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cartctl.cart import encoder_quantum_rad_s
from cartctl.data.modelfile import load_models
from cartctl.design.make import design_motor
from cartctl.design.request import DesignRequest
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.reference import reference_signal
from cartctl.runtime.base import Controller
from cartctl.runtime.loop import run_in_memory
from cartctl.runtime.pi import PiController
from cartctl.sinks.summary import motor_metrics
from cartctl.tune.batch import ArxBatch, simulate_batch
from cartctl.tune.robust import step_metrics

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
TS = 0.01


def _plants() -> list[ArxModel]:
    """The ground model of motor a, and five around it: θ within ±5 %, DC gain ±10 %, nk 1–4."""
    base = load_models(GROUND).motor("a")
    rng = np.random.default_rng(14)
    plants = [base]
    for nk in (1, 2, 3, 4, 3):
        theta = base.theta * (1.0 + 0.05 * rng.uniform(-1.0, 1.0, 4))
        theta[2:] *= rng.uniform(0.9, 1.1)
        plants.append(ArxModel.from_theta(theta, nk=nk))
    assert all(p.is_stable() for p in plants)
    return plants


def _real_loop(
    controller: Controller, plant: ArxModel, reference: np.ndarray, limit_v: float
) -> dict[str, np.ndarray]:
    """One plant through ``cartctl run --fast``'s loop (motor b idle at 0 rad/s)."""
    columns, state = run_in_memory(ArxPlant(plant, plant), {"a": controller},
                                   {"a": reference, "b": np.zeros(reference.size)},
                                   period_s=TS, voltage_limit_v=limit_v)  # fmt: skip
    assert state.failure is None
    return columns


CASES = [
    ("pi", {"phase_margin_deg": 65.0, "crossover_hz": 4.0}),
    ("pi", {"phase_margin_deg": 50.0, "crossover_hz": 8.0}),  # saturates on a 14 rad/s square
    ("pi", {"phase_margin_deg": 50.0, "crossover_hz": 8.0, "anti_windup": "back-calculation"}),
    ("pi", {"phase_margin_deg": 50.0, "crossover_hz": 8.0, "anti_windup": "none"}),
    ("pi", {"phase_margin_deg": 60.0, "crossover_hz": 6.0, "estimator": "kalman"}),
    ("poles", {"settling_time_s": 0.04, "overshoot_percent": 5.0}),
    ("poles", {"settling_time_s": 0.1, "overshoot_percent": 1.0}),
    ("poles", {"settling_time_s": 0.04, "overshoot_percent": 2.0}),
    ("poles", {"settling_time_s": 0.06, "overshoot_percent": 1.0, "bias_drift_std_v": 0.0}),
]  # fmt: skip


@pytest.mark.parametrize(("method", "options"), CASES)
def test_the_batch_loop_gives_the_real_loops_traces(method: str, options: dict) -> None:
    plants = _plants()
    request = DesignRequest(method=method, voltage_limit_v=12.0, **options)
    reference = reference_signal("square:14:0.8", 160, TS)
    batch = simulate_batch(design_motor(request, plants[0]).controller,
                           ArxBatch.from_models(plants), reference, voltage_limit_v=12.0)  # fmt: skip
    assert batch.speed.shape == batch.voltage.shape == (len(plants), 161)
    assert not batch.diverged.any()
    for i, plant in enumerate(plants):
        columns = _real_loop(design_motor(request, plants[0]).controller, plant, reference, 12.0)
        np.testing.assert_allclose(batch.speed[i], columns["speed_a"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(batch.voltage[i], columns["voltage_a"], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(batch.time_s, columns["time_s"])
        np.testing.assert_array_equal(batch.reference, columns["reference_a"])
        np.testing.assert_array_equal(columns["speed_a"], columns["true_speed_a"])  # no noise


def test_the_cases_cover_saturation_and_the_anti_windup_modes_differ() -> None:
    """The aggressive PI hits the limit on some plants, and the three modes then part ways."""
    plants = _plants()
    reference = reference_signal("square:14:0.8", 160, TS)
    speeds = {}
    for mode in ("conditional", "back-calculation", "none"):
        request = DesignRequest(method="pi", phase_margin_deg=50.0, crossover_hz=8.0,
                                anti_windup=mode)  # fmt: skip
        trace = simulate_batch(design_motor(request, plants[0]).controller,
                               ArxBatch.from_models(plants), reference)  # fmt: skip
        assert np.max(np.abs(trace.voltage)) == 12.0
        speeds[mode] = trace.speed
    assert not np.allclose(speeds["conditional"], speeds["none"])
    assert not np.allclose(speeds["back-calculation"], speeds["none"])


def test_a_lower_voltage_limit_and_a_hand_built_pi_with_its_tracking_gain() -> None:
    """A PiController built by hand (Kt given, 6 V limit), the loop's clamp at 6 V too."""
    plants = _plants()
    reference = reference_signal("step:12:0.1", 120, TS)

    def make() -> PiController:
        return PiController(1.2, 40.0, TS, voltage_limit_v=6.0, anti_windup="back-calculation",
                            tracking_gain=0.3)  # fmt: skip

    batch = simulate_batch(make(), ArxBatch.from_models(plants), reference, voltage_limit_v=6.0)
    assert np.max(np.abs(batch.voltage)) == 6.0
    for i, plant in enumerate(plants):
        columns = _real_loop(make(), plant, reference, 6.0)
        np.testing.assert_allclose(batch.speed[i], columns["speed_a"], rtol=0, atol=1e-9)
        np.testing.assert_allclose(batch.voltage[i], columns["voltage_a"], rtol=0, atol=1e-9)


def test_a_plant_that_runs_away_is_marked_where_the_real_loop_fails() -> None:
    """An unstable plant (a pole at z = 1.2) under a weak PI: the real loop stops with a plant
    fault; the batch marks that plant and leaves the stable one alone."""
    stable = load_models(GROUND).motor("a")
    unstable = ArxModel((-1.2, 0.0), stable.b, 2, TS)
    reference = reference_signal("step:1:0", 400, TS)

    def make() -> PiController:
        return PiController(0.01, 0.1, TS)

    columns, state = run_in_memory(ArxPlant(unstable, unstable), {"a": make(), "b": make()},
                                   {"a": reference, "b": reference}, period_s=TS,
                                   voltage_limit_v=12.0)  # fmt: skip
    assert state.failure is not None and "ran away" in state.failure
    batch = simulate_batch(make(), ArxBatch.from_models([stable, unstable]), reference)
    assert batch.diverged.tolist() == [False, True]
    ticks = columns["speed_a"].size - 1  # rows before the stop row
    np.testing.assert_allclose(batch.speed[1, :ticks], columns["speed_a"][:ticks], rtol=1e-12)
    metrics = step_metrics(batch, encoder_quantum_rad_s(TS))
    assert math.isinf(metrics["overshoot_percent"][1]) and math.isinf(metrics["settling_time_s"][1])
    assert math.isfinite(metrics["overshoot_percent"][0])


@pytest.mark.parametrize(
    ("spec", "ticks", "unsettled_is", "some_unsettled"),
    [("step:10", 200, math.inf, False), ("step:-8:0.2", 150, math.inf, False),
     ("square:14:0.8", 160, math.inf, True), ("step:10", 55, math.inf, True),
     ("ramp:20", 100, math.nan, True), ("const:0.2", 80, math.nan, True)],
)  # fmt: skip
def test_batch_metrics_are_the_run_summarys(
    spec: str, ticks: int, unsettled_is: float, some_unsettled: bool
) -> None:
    """Per plant, what ``motor_metrics`` (the summary of ``cartctl run``) says of the same trace.
    Where it says None for settling: a run that has not settled when its step ends is ``inf``; a
    ramp (no step) and a 0.2 rad/s step (inside its own band, one encoder count) are NaN."""
    plants = _plants()
    request = DesignRequest(method="pi", phase_margin_deg=55.0, crossover_hz=5.0)
    reference = reference_signal(spec, ticks, TS)
    trace = simulate_batch(design_motor(request, plants[0]).controller,
                           ArxBatch.from_models(plants), reference)  # fmt: skip
    floor = encoder_quantum_rad_s(TS)
    got = step_metrics(trace, floor)
    keys = {"overshoot_percent": "overshoot_percent", "settling_time_s": "settling_time_s",
            "rms_error": "rms_error", "peak_voltage_v": "max_abs_voltage"}  # fmt: skip
    unsettled = 0
    for i in range(len(plants)):
        want = motor_metrics(trace.time_s, trace.reference, trace.speed[i], trace.voltage[i],
                             settling_floor=floor)  # fmt: skip
        for ours, theirs in keys.items():
            value, expected = got[ours][i], want[theirs]
            if expected is not None:
                assert value == pytest.approx(expected, rel=1e-12, abs=1e-12), (ours, i)
            elif ours == "settling_time_s":
                unsettled += 1
                if math.isnan(unsettled_is):
                    assert math.isnan(value), (i, value)
                else:
                    assert value == unsettled_is, (i, value)
            else:
                assert math.isnan(value), (ours, i, value)
    assert (unsettled > 0) == some_unsettled
