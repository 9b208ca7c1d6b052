"""The RTS-smoothed speed (cartctl.design.kalman) on hand-made traces whose truth is known.

A trace made by the model itself is reproduced exactly; a constant input disturbance is found; an
encoder quantising the model's angle (floor of whole counts, as the cart's) is beaten by more than
half in RMS; a speed that rises linearly is estimated at the tick, not half a tick late; and the
physics simulator's seeded trace (its true speed recorded) through the same function.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cartctl.design.kalman import angle_noise_std_rad, smooth_speed
from cartctl.errors import InputError
from cartctl.model import ArxModel

TS = 0.01
GROUND_A = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751])  # the report's ground model
COUNT_RAD = 2.0 * math.pi / 1792


def _square(seed: int, levels: int = 12, hold: int = 25) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(-8.0, 8.0, levels), hold)


def _encoder(mean_speed_rad_s: np.ndarray, offset_rad: float = 0.3e-3) -> np.ndarray:
    """The cart's encoder speed for a mean speed per tick: whole counts of the floored angle."""
    angle = offset_rad + TS * np.cumsum(mean_speed_rad_s)
    counts = np.floor(angle / COUNT_RAD)
    return np.diff(np.concatenate([[math.floor(offset_rad / COUNT_RAD)], counts])) * COUNT_RAD / TS


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def test_a_trace_the_model_made_is_reproduced_exactly() -> None:
    u = _square(1)
    y = GROUND_A.simulate(u)  # noise-free: what the model says the encoder measures
    s = smooth_speed(GROUND_A, u, y)
    np.testing.assert_allclose(s.mean_speed_rad_s, y, atol=1e-9)
    np.testing.assert_allclose(s.bias_v, 0.0, atol=1e-9)


def test_a_constant_input_disturbance_is_estimated() -> None:
    u = _square(2)
    y = GROUND_A.simulate(u - 0.6)  # friction-like: 0.6 V lost at the input
    s = smooth_speed(GROUND_A, u, y, counts_per_rev=10**7)  # a nearly exact encoder
    assert np.median(s.bias_v[50:]) == pytest.approx(-0.6, abs=0.01)
    assert _rms(s.mean_speed_rad_s - y) < 0.01


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_smoothed_beats_the_encoder_by_more_than_half(seed: int) -> None:
    u = _square(seed)
    y = GROUND_A.simulate(u)
    measured = _encoder(y)
    assert np.all(
        np.abs(measured / (COUNT_RAD / TS) - np.round(measured / (COUNT_RAD / TS))) < 1e-6
    )
    s = smooth_speed(GROUND_A, u, measured)
    assert _rms(s.mean_speed_rad_s - y) < 0.5 * _rms(measured - y)


def test_the_speed_at_the_tick_is_the_midpoint_of_the_tick_means() -> None:
    # a speed that rises linearly: ω(t) = α t. The encoder means over [k − 1, k] are α (k − ½) Ts,
    # the true speed at tick k is α k Ts. An integrator model (y[k] = y[k−1] + g u[k−1]) with a
    # constant voltage produces exactly this ramp of means.
    gain = 0.05  # rad/s per V per tick
    model = ArxModel((-1.0,), (gain,), 1, TS)
    u = np.full(200, 4.0)
    y = model.simulate(u)  # y[k] = 0.2 k: the mean over the tick before k
    s = smooth_speed(model, u, y, counts_per_rev=10**7)
    true_at_tick = y + 0.5 * gain * 4.0  # half a tick of the ramp on
    np.testing.assert_allclose(s.speed_rad_s[1:], true_at_tick[1:], atol=1e-3)


def test_the_angle_noise_is_one_count_over_root_twelve() -> None:
    assert angle_noise_std_rad(1792) == pytest.approx(2 * math.pi / 1792 / math.sqrt(12))


def test_physics_trace_smoothed_rms_error_is_under_half_the_encoders(ground_path) -> None:
    from cartctl.data.modelfile import load_models
    from cartctl.plants.factory import make_plant

    plant, _ = make_plant("physics", seed=7)
    rng = np.random.default_rng(7)
    u = np.repeat(rng.uniform(-9.0, 9.0, 16), 30)
    speed, true = np.zeros(u.size), np.zeros(u.size)
    y = plant.reset()
    for k, v in enumerate(u):  # row k: the speed measured at k, the voltage commanded at k
        speed[k], true[k] = y.speed_a_rad_s, y.true_speed_a_rad_s
        y = plant.step(v, 0.0)
    model = load_models(ground_path).motor("a")
    s = smooth_speed(model, u, speed)
    assert _rms(s.speed_rad_s - true) <= 0.5 * _rms(speed - true)


def test_bad_input_is_refused() -> None:
    with pytest.raises(InputError, match="differ in length"):
        smooth_speed(GROUND_A, np.zeros(3), np.zeros(4))
    with pytest.raises(InputError, match="the speed is not finite at row 1"):
        smooth_speed(GROUND_A, np.zeros(3), np.array([0.0, math.nan, 0.0]))
    with pytest.raises(InputError, match="nk"):
        smooth_speed(ArxModel((-0.5,), (1.0,), 0, TS), np.zeros(3), np.zeros(3))
