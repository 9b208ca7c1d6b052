"""The simulated ARX plant: tick convention, agreement with the model, saturation, noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.errors import InputError
from cartctl.model import ArxModel
from cartctl.plants.base import Plant
from cartctl.plants.sim import ArxPlant, saturate
from cartctl.runtime.loop import run_experiment
from cartctl.signals import square

GROUND_A = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751])
GROUND_B = ArxModel.from_theta([-0.9082, 0.1968, 0.6886, -0.1068])


def test_is_a_plant() -> None:
    assert isinstance(ArxPlant(GROUND_A, GROUND_B), Plant)


@pytest.mark.parametrize("nk", [1, 2, 3])
def test_experiment_trace_equals_model_simulation(nk: int) -> None:
    ma = ArxModel.from_theta(GROUND_A.theta, nk=nk)
    rng = np.random.default_rng(nk)
    ua, ub = rng.uniform(-12, 12, 500), square(10.0, cycles=2)[:500]
    trace = run_experiment(ArxPlant(ma, GROUND_B), ua, ub).trace
    np.testing.assert_allclose(trace.speed_a, ma.simulate(ua), atol=1e-12)
    np.testing.assert_allclose(trace.speed_b, GROUND_B.simulate(ub), atol=1e-12)
    np.testing.assert_array_equal(trace.voltage_a, ua)
    np.testing.assert_allclose(trace.time_s, np.arange(500) * 0.01)
    np.testing.assert_array_equal(trace.extra["true_speed_a"], trace.speed_a)


def test_delay_of_two_ticks() -> None:
    plant = ArxPlant(GROUND_A, GROUND_B)
    plant.reset()
    y1 = plant.step(10.0, 0.0)  # v[0] = 10 → y[1] still 0
    y2 = plant.step(10.0, 0.0)  # y[2] = a v[0]
    assert y1.speed_a_rad_s == 0.0
    assert y2.speed_a_rad_s == pytest.approx(0.6466 * 10.0)


def test_voltage_saturates_at_supply() -> None:
    plant_hi, plant_12 = ArxPlant(GROUND_A, GROUND_B), ArxPlant(GROUND_A, GROUND_B)
    for p in (plant_hi, plant_12):
        p.reset()
    for _ in range(50):
        hi = plant_hi.step(100.0, -100.0)
        at = plant_12.step(12.0, -12.0)
    assert hi == at


@settings(max_examples=50, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_saturate_always_within_limit(v: float) -> None:
    out = saturate(v, 12.0)
    assert -12.0 <= out <= 12.0
    if not math.isfinite(v):
        assert out == 0.0


def test_noise_is_off_by_default_and_seeded_when_on() -> None:
    u = square(10.0, cycles=1)
    clean = run_experiment(ArxPlant(GROUND_A, GROUND_B), u, u).trace
    noisy1 = run_experiment(ArxPlant(GROUND_A, GROUND_B, noise_std_rad_s=0.3, seed=7), u, u).trace
    noisy2 = run_experiment(ArxPlant(GROUND_A, GROUND_B, noise_std_rad_s=0.3, seed=7), u, u).trace
    noisy3 = run_experiment(ArxPlant(GROUND_A, GROUND_B, noise_std_rad_s=0.3, seed=8), u, u).trace
    np.testing.assert_array_equal(noisy1.speed_a, noisy2.speed_a)
    assert not np.array_equal(noisy1.speed_a, noisy3.speed_a)
    residual = noisy1.speed_a - clean.speed_a
    assert residual.std() == pytest.approx(0.3, rel=0.15)
    np.testing.assert_array_equal(noisy1.extra["true_speed_a"], clean.speed_a)


def test_reset_returns_to_rest() -> None:
    plant = ArxPlant(GROUND_A, GROUND_B)
    u = square(10.0, cycles=1)
    first = run_experiment(plant, u, u).trace
    second = run_experiment(plant, u, u).trace
    np.testing.assert_array_equal(first.speed_b, second.speed_b)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"model_b": ArxModel.from_theta(GROUND_B.theta, period_s=0.02)},
            "different sample periods",
        ),
        ({"model_b": ArxModel.from_theta(GROUND_B.theta, nk=0)}, "nk >= 1"),
        ({"noise_std_rad_s": -1.0}, "noise"),
    ],
)
def test_bad_plants_are_refused(kwargs: dict, message: str) -> None:
    args = {"model_a": GROUND_A, "model_b": GROUND_B, **kwargs}
    with pytest.raises(InputError, match=message):
        ArxPlant(**args)


class _InterruptingPlant(ArxPlant):
    def __init__(self) -> None:
        super().__init__(GROUND_A, GROUND_B)
        self.commands: list[tuple[float, float]] = []
        self.closed = False

    def step(self, voltage_a_v: float, voltage_b_v: float):
        if len(self.commands) == 30:
            raise KeyboardInterrupt
        self.commands.append((voltage_a_v, voltage_b_v))
        return super().step(voltage_a_v, voltage_b_v)

    def close(self) -> None:
        self.closed = True


def test_ctrl_c_keeps_the_ticks_recorded_and_closes_the_plant() -> None:
    plant = _InterruptingPlant()
    u = np.full(100, 5.0)
    result = run_experiment(plant, u, u)
    assert result.interrupted
    assert plant.closed
    assert len(result.trace) == 31  # ticks 0..30 were measured; the 31st command never went out


def test_the_recorded_loop_delay_holds_only_where_the_models_delay_fits_it() -> None:
    """A model file records the loop its data came from; a model whose nk is neither that delay
    nor one more (edited to answer later) is a longer loop: nk − 1."""
    from cartctl.model import ArxModel
    from cartctl.plants.sim import ArxPlant

    def model(nk: int) -> ArxModel:
        return ArxModel(ar=(-0.6, 0.0), b=(0.5, 0.3), nk=nk, period_s=0.01)

    assert ArxPlant(model(2), model(2), loop_delay_ticks=1).loop_delay_ticks == 1
    assert ArxPlant(model(1), model(1), loop_delay_ticks=1).loop_delay_ticks == 1
    assert ArxPlant(model(4), model(4), loop_delay_ticks=1).loop_delay_ticks == 3
    assert ArxPlant(model(2), model(4), loop_delay_ticks=1).loop_delay_ticks == 3
    assert ArxPlant(model(3), model(3)).loop_delay_ticks == 2
