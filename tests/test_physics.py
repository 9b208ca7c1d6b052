"""Tests of the physical cart simulator (cartctl.plants.physics)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import cont2discrete

from cartctl.errors import InputError
from cartctl.plants.base import Measurement, Plant
from cartctl.plants.physics import PhysicsPlant
from cartctl.plants.physics_params import PRESETS, CartParams, MotorParams, preset

TS_S = 0.01
SPEED_STEP_RAD_S = 2.0 * math.pi / 1792 / TS_S
PWM_STEP_V = 12.0 / 255.0

# The report's models, θ = [c, d, a, b] (equations 8 and 12).
REPORT_THETA = {
    ("air", 0): (-0.5393, 0.0373, 1.081, -0.0323),
    ("air", 1): (-0.5886, 0.05778, 1.06, -0.07238),
    ("ground", 0): (-0.9356, 0.2173, 0.6466, -0.07751),
    ("ground", 1): (-0.9082, 0.1968, 0.6886, -0.1068),
}


def square_wave(cycles: int = 5) -> np.ndarray:
    """+10 V, 0 V, −10 V for 1 s each, repeated (the report's excitation), one value per tick."""
    return np.tile(np.repeat([10.0, 0.0, -10.0], 100), cycles)


def run(
    plant: PhysicsPlant, voltage_a_v: np.ndarray, voltage_b_v: np.ndarray | None = None
) -> np.ndarray:
    """Row k: what was measured at tick k, as an array (n, 4): speeds then true speeds."""
    voltage_b_v = voltage_a_v if voltage_b_v is None else voltage_b_v
    out = np.empty((len(voltage_a_v), 4))
    m = plant.reset()
    for k, (va, vb) in enumerate(zip(voltage_a_v.tolist(), voltage_b_v.tolist(), strict=True)):
        out[k] = (m.speed_a_rad_s, m.speed_b_rad_s, m.true_speed_a_rad_s, m.true_speed_b_rad_s)
        m = plant.step(va, vb)
    return out


def arx_features(voltage_v: np.ndarray, speed_rad_s: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares fit of the report's equation 6; return (the two poles, DC gain)."""
    phi = np.column_stack([-speed_rad_s[2:-1], -speed_rad_s[1:-2], voltage_v[1:-2], voltage_v[:-3]])
    theta, *_ = np.linalg.lstsq(phi, speed_rad_s[3:], rcond=None)
    return model_features(theta)


def model_features(theta: np.ndarray | tuple[float, ...]) -> tuple[np.ndarray, float]:
    """(the two poles of z² + c z + d, DC gain) of θ = [c, d, a, b]."""
    c, d, a, b = theta
    return np.roots([1.0, c, d]).astype(complex), (a + b) / (1.0 + c + d)


def pole_hz(poles: np.ndarray) -> np.ndarray:
    """Continuous-equivalent frequencies |ln p| / (2π Ts), ascending (Hz)."""
    return np.sort(np.abs(np.log(poles)) / (2.0 * math.pi * TS_S))


def theta_tolerance(theta: tuple[float, ...]) -> np.ndarray:
    """10 % of each θ, or 0.03 absolute for b and for any term below 0.1 (d in the air)."""
    t = 0.1 * np.abs(theta)
    small = np.abs(theta) < 0.1
    small[3] = True
    t[small] = np.maximum(t[small], 0.03)
    return t


def report_procedure_errors(name: str, tmp_path, capsys) -> dict[str, np.ndarray]:
    """The report's procedure through the CLI (a 10 V square cycle, then the unfiltered ARX fit
    with nk = 2); per motor, (θ − θ of equation 8 / 12) in tolerances."""
    from cartctl.cli import main

    data = tmp_path / f"{name}.csv"
    argv = ["excite", "--plant", "physics", "--preset", name, "--signal", "square"]
    assert main([*argv, "--amplitude", "10", "--out", str(data)]) == 0
    capsys.readouterr()
    assert main(["identify", str(data), "--delay", "2", "--json"]) == 0
    motors = json.loads(capsys.readouterr().out)["motors"]
    out = {}
    for motor, index in (("a", 0), ("b", 1)):
        want = np.array(REPORT_THETA[(name, index)])
        out[motor] = (np.array(motors[motor]["theta"]) - want) / theta_tolerance(want)
    return out


def test_air_preset_gives_back_all_four_theta_of_equation_8(tmp_path, capsys) -> None:
    for motor, err in report_procedure_errors("air", tmp_path, capsys).items():
        assert np.all(np.abs(err) <= 1.0), (motor, err)


def test_ground_preset_gives_back_all_four_theta_of_equation_12(tmp_path, capsys) -> None:
    for motor, err in report_procedure_errors("ground", tmp_path, capsys).items():
        assert np.all(np.abs(err) <= 1.0), (motor, err)


@pytest.mark.parametrize("name", ["air", "ground"])
def test_arx_poles_and_gain_hold_over_encoder_start_offsets(name: str) -> None:
    voltage = square_wave()
    for offset in (0.25, 0.5, 0.75):
        plant = PhysicsPlant(name)
        q = 2.0 * math.pi / 1792
        out = np.empty((voltage.size, 2))
        m = plant.reset(position_rad=(offset * q, offset * q))
        for k, v in enumerate(voltage.tolist()):
            out[k] = (m.speed_a_rad_s, m.speed_b_rad_s)
            m = plant.step(v, v)
        for motor in (0, 1):
            poles, gain = arx_features(voltage, out[:, motor])
            want_poles, want_gain = model_features(REPORT_THETA[(name, motor)])
            assert np.all(np.abs(poles) < 1.0)
            # the slow pole; the fast one is set by the encoder's quantisation pattern. On the
            # ground the quantisation bias of this fit moves the slow pole by up to −21 % with the
            # start offset (8.5–10.2 Hz against the report's 10.8): hence 25 % there.
            rel = 0.2 if name == "air" else 0.25
            assert pole_hz(poles)[0] == pytest.approx(pole_hz(want_poles)[0], rel=rel)
            assert gain == pytest.approx(want_gain, rel=0.05)


def test_is_a_plant_and_starts_at_rest() -> None:
    plant = PhysicsPlant()
    assert isinstance(plant, Plant)
    assert plant.period_s == TS_S
    assert plant.reset() == Measurement(0.0, 0.0, 0.0, 0.0)
    assert plant.applied_voltage_v == (0.0, 0.0)
    assert plant.position_rad == (0.0, 0.0)


def test_saturation_and_pwm_quantisation() -> None:
    plant = PhysicsPlant("air")
    plant.reset()
    plant.step(20.0, -1e9)
    assert plant.applied_voltage_v == (12.0, -12.0)
    plant.step(5.0, -0.03)
    assert plant.applied_voltage_v == (round(5.0 / PWM_STEP_V) * PWM_STEP_V, -PWM_STEP_V)
    assert plant.last_interval_voltage_v == (12.0, -12.0)


@given(st.floats(allow_nan=True, allow_infinity=True))
@settings(max_examples=100, deadline=None)  # each builds a plant (~10 ms)
def test_applied_voltage_is_bounded_on_the_grid_and_safe(command: float) -> None:
    plant = PhysicsPlant("air")
    plant.step(command, -command)
    for applied in plant.applied_voltage_v:
        assert -12.0 <= applied <= 12.0
        steps = applied / PWM_STEP_V
        assert steps == pytest.approx(round(steps), abs=1e-9)
    if not math.isfinite(command):
        assert plant.applied_voltage_v == (0.0, 0.0)


@pytest.mark.parametrize("k", [0, 7])
def test_documented_order_applies_a_command_one_tick_later(k: int) -> None:
    # actuation_delay_s None: microOS's documented order, the next tick's io() writes the command
    plant = PhysicsPlant(replace(preset("air"), actuation_delay_s=None))
    plant.reset()
    for _ in range(k):
        plant.step(0.0, 0.0)
    m1 = plant.step(10.0, -10.0)  # commanded at tick k; m1 is tick k + 1
    assert (m1.true_speed_a_rad_s, m1.true_speed_b_rad_s) == (0.0, 0.0)
    assert plant.armature_current_amp == (0.0, 0.0)
    assert (m1.speed_a_rad_s, m1.speed_b_rad_s) == (0.0, 0.0)
    assert plant.applied_voltage_v == pytest.approx((9.976, -9.976), abs=1e-3)
    m2 = plant.step(0.0, 0.0)  # tick k + 2: the first speed the command shows in
    assert m2.true_speed_a_rad_s > 0.0 > m2.true_speed_b_rad_s
    assert m2.speed_a_rad_s > 0.0 > m2.speed_b_rad_s
    assert plant.last_interval_voltage_v == pytest.approx((9.976, -9.976), abs=1e-3)


@pytest.mark.parametrize("name", ["air", "ground"])
def test_presets_apply_a_command_within_the_next_tick(name: str) -> None:
    # The calibrated presets: the command drives the motor from actuation_delay_s after its tick
    # on, so it shows a little in the next tick's average speed and mostly in the one after.
    params = preset(name)
    delay = params.actuation_delay()
    assert 0.0 < delay < params.period_s
    plant = PhysicsPlant(params)
    plant.reset()
    plant.step(0.0, 0.0)
    m1 = plant.step(10.0, 10.0)
    assert plant.last_interval_voltage_v == (0.0, 0.0)  # until the command landed
    assert m1.true_speed_a_rad_s > 0.0  # it landed inside the tick
    m2 = plant.step(10.0, 10.0)
    assert 0.0 <= m1.speed_a_rad_s < 0.4 * m2.speed_a_rad_s
    # the same motor with the command landing one whole tick later lags behind by that tick
    late = PhysicsPlant(replace(params, actuation_delay_s=None))
    late.reset()
    late.step(0.0, 0.0)
    late.step(10.0, 10.0)
    assert late.step(10.0, 10.0).true_speed_a_rad_s < m2.true_speed_a_rad_s


def test_actuation_delay_must_fit_the_substeps() -> None:
    with pytest.raises(InputError, match="actuation_delay_s"):
        replace(preset("air"), actuation_delay_s=0.0025)
    with pytest.raises(InputError, match="actuation_delay_s"):
        replace(preset("air"), actuation_delay_s=0.02)


def test_measured_speed_is_whole_counts_per_tick() -> None:
    data = run(PhysicsPlant("ground"), square_wave(cycles=1))
    counts = data[:, :2] / SPEED_STEP_RAD_S
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert np.abs(counts).max() > 50  # it did move
    # and the encoder agrees: counts are floor(θ / (2π/1792))
    plant = PhysicsPlant("ground")
    plant.reset()
    for _ in range(37):
        plant.step(3.0, -5.0)
    for theta, count in zip(plant.position_rad, plant.encoder_counts, strict=True):
        assert count == math.floor(theta / (2.0 * math.pi / 1792))


def test_zero_volts_brakes_to_exactly_zero_and_stays() -> None:
    params = preset("air")
    voltage = np.r_[np.full(100, 10.0), np.zeros(200)]
    data = run(PhysicsPlant(params), voltage)
    for motor, m in enumerate((params.motor_a, params.motor_b)):
        true_speed = data[100:, 2 + motor]
        first = int(np.flatnonzero(true_speed == 0.0)[0])
        assert np.all(true_speed[first:] == 0.0)  # no chattering around zero
        assert np.all(data[100 + first + 1 :, motor] == 0.0)  # the encoder stops a tick later
        # Coasting (open terminals, i = 0): J dω/dt = −b ω − τ_c stops after (J/b) ln(1 + bω0/τ_c).
        j, b, tc = m.inertia_kg_m2, m.viscous_n_m_s, m.coulomb_n_m
        coast_s = j / b * math.log(1.0 + b * true_speed[0] / tc)
        assert first * TS_S < 0.5 * coast_s


@pytest.mark.parametrize(
    ("name", "below_v", "above_v"), [("air", 0.25, 0.45), ("ground", 0.7, 0.95)]
)
def test_coulomb_friction_holds_below_breakaway(name: str, below_v: float, above_v: float) -> None:
    plant = PhysicsPlant(name)
    plant.reset()
    for _ in range(200):
        m = plant.step(below_v, -below_v)
    assert (m.true_speed_a_rad_s, m.true_speed_b_rad_s) == (0.0, 0.0)
    assert plant.position_rad == (0.0, 0.0)
    for _ in range(50):
        m = plant.step(above_v, -above_v)
    assert m.true_speed_a_rad_s > 0.0 > m.true_speed_b_rad_s


def test_reversal_passes_through_zero_without_sticking() -> None:
    voltage = np.r_[np.full(100, 10.0), np.full(100, -10.0)]
    data = run(PhysicsPlant("ground"), voltage)
    assert data[100, 2] > 15.0
    assert data[-1, 2] < -15.0
    assert np.count_nonzero(data[101:, 2] == 0.0) <= 1


def test_noise_off_by_default_and_seeded_noise_reproducible() -> None:
    voltage = square_wave(cycles=1)
    quiet = run(PhysicsPlant("ground"), voltage)
    np.testing.assert_array_equal(quiet, run(PhysicsPlant("ground"), voltage))
    noisy = run(PhysicsPlant("ground", noise_std_rad_s=0.5, seed=3), voltage)
    np.testing.assert_array_equal(
        noisy, run(PhysicsPlant("ground", noise_std_rad_s=0.5, seed=3), voltage)
    )
    other = run(PhysicsPlant("ground", noise_std_rad_s=0.5, seed=4), voltage)
    assert not np.array_equal(noisy[:, :2], other[:, :2])
    np.testing.assert_array_equal(noisy[:, 2:], quiet[:, 2:])  # noise is in the sensor only
    residual = noisy[:, :2] - quiet[:, :2]
    assert residual.std() == pytest.approx(0.5, rel=0.15)


def test_reset_restores_rest() -> None:
    voltage = square_wave(cycles=1)[:150]
    plant = PhysicsPlant("ground")
    first = run(plant, voltage)
    assert plant.position_rad != (0.0, 0.0)
    assert plant.reset() == Measurement(0.0, 0.0, 0.0, 0.0)
    assert plant.position_rad == (0.0, 0.0)
    assert plant.applied_voltage_v == (0.0, 0.0)
    assert plant.armature_current_amp == (0.0, 0.0)
    np.testing.assert_array_equal(run(plant, voltage), first)


def test_close_commands_zero_volts() -> None:
    plant = PhysicsPlant()
    plant.reset()
    plant.step(6.0, 6.0)
    plant.close()
    assert plant.applied_voltage_v == (0.0, 0.0)


def test_unknown_preset_lists_valid_names() -> None:
    with pytest.raises(InputError, match="air, ground"):
        PhysicsPlant("moon")
    with pytest.raises(ValueError, match="unknown physics preset 'moon'"):
        preset("moon")
    assert set(PRESETS) == {"air", "ground"}


@pytest.mark.parametrize(
    "bad",
    [{"inertia_kg_m2": -1.0}, {"inductance_h": 0.0}, {"coulomb_n_m": float("nan")}],
)
def test_bad_parameters_are_refused(bad: dict[str, float]) -> None:
    with pytest.raises(InputError, match=next(iter(bad))):
        replace(preset("air").motor_a, **bad)
    with pytest.raises(InputError, match="noise_std_rad_s"):
        PhysicsPlant("air", noise_std_rad_s=-1.0)


def test_without_dry_friction_it_is_the_exact_zoh_model() -> None:
    motor = replace(preset("air").motor_a, coulomb_n_m=0.0)
    plant = PhysicsPlant(CartParams("linear", motor, motor))
    rng = np.random.default_rng(0)
    voltage = np.repeat(rng.uniform(-12.0, 12.0, 40), 5)
    data = run(plant, voltage)
    j, b, k = motor.inertia_kg_m2, motor.viscous_n_m_s, motor.torque_constant_n_m_a
    r, ind = motor.resistance_ohm, motor.inductance_h
    a_c = np.array([[-r / ind, -k / ind], [k / j, -b / j]])
    a_d, b_d, *_ = cont2discrete(
        (a_c, np.array([[1.0 / ind], [0.0]]), np.eye(2), np.zeros((2, 1))), TS_S
    )
    applied = np.array([plant.condition_voltage(v) for v in voltage])
    x = np.zeros(2)
    expected = [0.0, 0.0]  # ticks 0 and 1: the first command acts from tick 1 on
    for v in applied[:-2]:
        x = a_d @ x + b_d[:, 0] * v
        expected.append(x[1])
    np.testing.assert_allclose(data[:, 2], expected, atol=1e-9)


def test_substeps_only_set_event_resolution() -> None:
    voltage = np.r_[square_wave(cycles=1), np.full(50, 0.3), np.full(50, -2.0)]
    ground = preset("ground")  # its actuation delay is a whole number of 1 ms and 0.25 ms substeps
    coarse = run(PhysicsPlant(replace(ground, substeps=10)), voltage)
    fine = run(PhysicsPlant(replace(ground, substeps=40)), voltage)
    np.testing.assert_allclose(coarse[:, 2:], fine[:, 2:], atol=1e-6)


def test_start_offset_between_encoder_edges() -> None:
    rad_per_count = 2.0 * math.pi / 1792
    plant = PhysicsPlant("air")
    assert plant.reset(position_rad=(0.5 * rad_per_count, 10.2 * rad_per_count)) == Measurement(
        0.0, 0.0, 0.0, 0.0
    )
    assert plant.encoder_counts == (0, 10)


def test_motor_params_carry_units_in_names() -> None:
    fields = set(MotorParams.__dataclass_fields__)
    assert fields == {
        "inertia_kg_m2",
        "viscous_n_m_s",
        "coulomb_n_m",
        "torque_constant_n_m_a",
        "resistance_ohm",
        "inductance_h",
    }


def test_params_serialise_for_provenance() -> None:
    as_dict = preset("ground").to_dict()
    assert as_dict["motor_a"]["inductance_h"] == preset("ground").motor_a.inductance_h
    assert json.loads(json.dumps(as_dict)) == as_dict
