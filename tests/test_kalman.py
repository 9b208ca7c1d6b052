"""The Kalman speed estimator: design invariants, the two runtime filters, and accuracy on physics.

The filters' x̂_1[k|k] estimates the measured speed, the average over the last tick; the state
feedback reports the mean of it and the next tick's predicted average, the true speed now (the
shipped controller's estimate against the true speed: tests/test_shipped_targets.py). Accuracy of
x̂_1 is judged against the true speed half a tick earlier, (ω[k−1] + ω[k]) / 2: the measured
speed is a count difference over the last tick, so it (and the model fitted to it, whose x_1 the
estimator tracks) is the tick-average speed, which lags the instantaneous ω[k] by about half a
tick. The lag test then checks, against the instantaneous ω, that the estimate is no more than one
tick late (it is about half a tick late, as the average is).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import control
import numpy as np
import pytest

from cartctl.data.modelfile import load_models
from cartctl.design.kalman import KalmanDesign, design_kalman, quantisation_std_rad_s, realise
from cartctl.design.pi import design_pi
from cartctl.design.poles import design_poles
from cartctl.errors import DataFileError, InputError
from cartctl.identification.arx import fit_arx
from cartctl.identification.oe import fit_oe
from cartctl.model import ArxModel
from cartctl.plants.physics import PhysicsPlant
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.base import SpeedEstimator
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.loop import run_experiment
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController

ROOT = Path(__file__).resolve().parents[1]
REPORT_A = ArxModel((-0.9356, 0.2173), (0.6466, -0.07751))


@pytest.fixture
def ground(ground_path) -> tuple[ArxModel, ArxModel]:
    models = load_models(ground_path)
    return models.motor("a"), models.motor("b")


# -- design --------------------------------------------------------------------------------------


def test_quantisation_noise_of_a_count_difference() -> None:
    q = (2 * math.pi / 1792) / 0.01
    assert q == pytest.approx(0.3506, abs=1e-4)
    assert quantisation_std_rad_s(0.01) == pytest.approx(q / math.sqrt(6))
    variance = design_kalman(REPORT_A, extra_noise_std_rad_s=0.2).R
    assert variance == pytest.approx(q**2 / 6 + 0.04)


@pytest.mark.parametrize("bias", [0.0, 0.03])
def test_filter_gain_solves_the_riccati_equation(bias: float) -> None:
    d = design_kalman(REPORT_A, bias_drift_std_v=bias)
    m = 3 + (bias > 0)
    assert d.A.shape == (m, m) and d.has_bias == (bias > 0) and d.n_model_states == 3
    A, C, P, R = d.A, d.C, d.P, d.R
    riccati = A @ P @ A.T - np.outer(A @ P @ C, C @ P @ A.T) / (C @ P @ C + R) + d.Q
    np.testing.assert_allclose(P, riccati, atol=1e-12)
    np.testing.assert_allclose(d.L, P @ C / (C @ P @ C + R))
    # python-control's dlqe gives the predictor gain A L (and the same P)
    predictor, P_ctrl, _ = control.dlqe(A, np.eye(m), C.reshape(1, m), d.Q, [[R]])
    np.testing.assert_allclose(np.ravel(predictor), A @ d.L, atol=1e-12)
    np.testing.assert_allclose(P_ctrl, P, atol=1e-12)
    poles = d.poles()
    np.testing.assert_allclose(
        np.sort_complex(poles),
        np.sort_complex(np.linalg.eigvals((np.eye(m) - np.outer(d.L, C)) @ A)),
        atol=1e-12,
    )
    assert np.all(np.abs(poles) < 1.0)
    np.testing.assert_allclose(d.posterior_covariance(), P - np.outer(d.L, C @ P), atol=1e-12)


def test_design_on_a_realisation_and_to_dict() -> None:
    d = design_kalman(realise(REPORT_A, extra_delay_ticks=1))
    assert d.A.shape == (5, 5)
    out = json.loads(json.dumps(d.to_dict()))
    assert len(out["estimator_poles"]) == 5 and out["has_bias"] is True


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"process_noise_std_v": 0.0}, "process_noise_std_v"),
        ({"process_noise_std_v": math.nan}, "process_noise_std_v"),
        ({"bias_drift_std_v": -0.1}, "bias_drift_std_v"),
        ({"extra_noise_std_rad_s": -1.0}, "extra_noise_std_rad_s"),
        ({"counts_per_rev": 0}, "counts_per_rev"),
    ],
)
def test_rejections(kwargs, words) -> None:
    with pytest.raises(InputError, match=words):
        design_kalman(REPORT_A, **kwargs)


def test_extra_delay_only_with_a_model() -> None:
    with pytest.raises(InputError, match="extra_delay_ticks"):
        design_kalman(realise(REPORT_A), extra_delay_ticks=1)


# -- the runtime estimators ----------------------------------------------------------------------


def drive(estimators: list[SpeedEstimator], ticks: int, seed: int = 5) -> None:
    """Feed the estimators the same noisy ARX-plant data, in the runtime's order."""
    rng = np.random.default_rng(seed)
    plant = ArxPlant(REPORT_A, REPORT_A, noise_std_rad_s=0.15, seed=seed)
    y = plant.reset()
    for u in 5.0 + 3.0 * rng.standard_normal(ticks):
        for e in estimators:
            e.correct(y.speed_a_rad_s)
            e.predict(float(u))
        y = plant.step(float(u), 0.0)


def test_from_the_steady_state_covariance_the_propagated_filter_is_the_fixed_one() -> None:
    """Without timing noise a design's P is stationary: filterpy's filter started from it gives
    the fixed-gain estimates, and so does the runtime's propagated filter."""
    from filterpy.kalman import KalmanFilter

    design = design_kalman(REPORT_A, bias_drift_std_v=0.03)
    m = design.A.shape[0]
    kf = KalmanFilter(dim_x=m, dim_z=1, dim_u=1)
    kf.F, kf.B, kf.H = design.A.copy(), design.B.reshape(m, 1), design.C.reshape(1, m)
    kf.Q, kf.R, kf.P = design.Q.copy(), np.array([[design.R]]), design.P.copy()
    varying, fixed = KalmanSpeedEstimator(design), SteadyStateSpeedEstimator(design)
    assert isinstance(varying, SpeedEstimator) and isinstance(fixed, SpeedEstimator)
    drive([varying, fixed], 50)
    np.testing.assert_allclose(varying.state, fixed.state, atol=1e-9)
    np.testing.assert_allclose(varying.gain, design.L, rtol=1e-9)
    rng = np.random.default_rng(3)
    for y, u in zip(rng.normal(8.0, 2.0, 200), rng.normal(3.0, 2.0, 200), strict=True):
        kf.update(float(y))
        np.testing.assert_allclose(kf.K[:, 0], design.L, rtol=1e-9)  # the gain never moves
        kf.predict(u=float(u))


@pytest.mark.parametrize("name", ["poles.toml", "serial-poles.toml"])
def test_shipped_time_varying_estimators_match_filterpy(name: str) -> None:
    """The fixed gain without timing noise (serial-poles.toml); the propagated filter with Q set per
    step where the file has timing noise (poles.toml): the runtime estimator against filterpy."""
    from filterpy.kalman import KalmanFilter

    from cartctl.design.controller_ss import kalman_from_entry
    from cartctl.design.controllerfile import build_controllers, load_controller

    controller = load_controller(ROOT / "controllers" / name)
    assert "estimator_gain" not in controller.request
    for motor, ctrl in build_controllers(controller).items():
        design = kalman_from_entry(controller.motors[motor]["estimator"])
        sigma = design.timing_noise_std_ticks  # poles.toml: Q moves with each command change
        assert isinstance(
            ctrl.estimator, KalmanSpeedEstimator if sigma else SteadyStateSpeedEstimator
        )
        m = design.A.shape[0]
        kf = KalmanFilter(dim_x=m, dim_z=1, dim_u=1)  # filterpy itself, from the file's matrices
        kf.F, kf.B, kf.H = design.A.copy(), design.B.reshape(m, 1), design.C.reshape(1, m)
        kf.Q, kf.R, kf.P = design.Q.copy(), np.array([[design.R]]), design.P.copy()
        rng = np.random.default_rng(7)
        fixed = ctrl.estimator
        previous = 0.0
        for y, u in zip(rng.normal(8.0, 2.0, 500), rng.normal(3.0, 2.0, 500), strict=True):
            kf.update(float(y))
            assert fixed.correct(float(y)) == pytest.approx(kf.x[0, 0], abs=1e-9)
            # Q per step: the timing error of the command change, (σ Δu)² B Bᵀ more
            kf.Q = design.Q + (sigma * (u - previous)) ** 2 * np.outer(design.B, design.B)
            previous = u
            kf.predict(u=float(u))
            fixed.predict(float(u))


def test_the_gain_moves_only_with_timing_noise() -> None:
    import dataclasses

    from cartctl.design.controllerfile import make_estimator

    design = design_kalman(REPORT_A)
    assert isinstance(make_estimator(design), SteadyStateSpeedEstimator)
    moved = dataclasses.replace(design, P=design.P * 10.0)  # a hand-edited P: still the fixed L
    assert isinstance(make_estimator(moved), SteadyStateSpeedEstimator)
    timed = dataclasses.replace(design, timing_noise_std_ticks=0.5)
    assert isinstance(make_estimator(timed), KalmanSpeedEstimator)


@pytest.mark.parametrize("kind", [KalmanSpeedEstimator, SteadyStateSpeedEstimator])
def test_non_finite_values_do_not_poison_the_state(kind) -> None:
    est = kind(design_kalman(REPORT_A))
    est.correct(3.0)
    est.predict(5.0)
    prior = est.state
    assert est.correct(math.nan) == pytest.approx(prior[0])
    np.testing.assert_array_equal(est.state, prior)
    est.predict(math.inf)  # counts as 0 V
    assert np.all(np.isfinite(est.state))
    est.reset()
    np.testing.assert_array_equal(est.state, np.zeros(4))


# -- what the estimate represents ----------------------------------------------------------------


def test_state_feedback_reports_the_speed_between_two_tick_averages(ground) -> None:
    """On an exact model the filter is exact, and the estimate the controller reports is the
    mean of this tick's measured average and the next one: the true speed now, for a speed that
    changes linearly over the two ticks."""
    design = design_poles(ground[0], settling_time_s=0.045, overshoot_percent=1.0)
    ctrl = StateFeedbackController(design)
    plant = ArxPlant(*ground)
    y = plant.reset()
    measured, estimate = [], []
    for k in range(120):
        u = ctrl.step(10.0 if k >= 5 else 0.0, y.speed_a_rad_s)
        measured.append(y.speed_a_rad_s)
        estimate.append(ctrl.estimate_rad_s)
        y = plant.step(u, 0.0)
    measured.append(y.speed_a_rad_s)
    m = np.array(measured)
    np.testing.assert_allclose(estimate, 0.5 * (m[:-1] + m[1:]), atol=1e-9)


def test_a_file_with_more_gains_than_estimator_states_is_refused(tmp_path: Path) -> None:
    """A hand-edited poles file whose K holds a gain more than its estimator has states is
    refused at loading (the extra gain would act on no state), not run without that gain."""
    from cartctl.design.controllerfile import build_controllers, load_controller

    text = (ROOT / "controllers" / "poles.toml").read_text(encoding="utf-8")
    edited = text.replace("    1.0,\n]\nKi = 0.0", "    1.0,\n    0.5,\n]\nKi = 0.0", 1)
    assert edited != text
    path = tmp_path / "five.toml"
    path.write_text(edited, encoding="utf-8")
    with pytest.raises(DataFileError, match=r"state of at least 5 values"):
        build_controllers(load_controller(path))


class OffsetPlant(ArxPlant):
    """The report's motor A with a constant voltage lost on the way, as dry friction takes it."""

    def __init__(self, offset_v: float) -> None:
        super().__init__(REPORT_A, REPORT_A)
        self.offset_v = offset_v

    def step(self, voltage_a_v: float, voltage_b_v: float):
        return super().step(voltage_a_v - self.offset_v, voltage_b_v - self.offset_v)


@pytest.mark.parametrize(("bias", "static_error"), [(0.03, False), (0.0, True)])
def test_pi_on_the_estimate_needs_the_disturbance_state(bias: float, static_error: bool) -> None:
    """The PI regulates its estimate: without the disturbance state the estimate carries the lost
    voltage as a speed offset, and so does the measured speed the PI leaves behind."""
    design = design_pi(REPORT_A, phase_margin_deg=70.0, crossover_hz=3.75)
    estimator = SteadyStateSpeedEstimator(design_kalman(REPORT_A, bias_drift_std_v=bias))
    ctrl = PiController(design.kp, design.ki, 0.01, estimator=estimator)
    plant = OffsetPlant(0.8)
    y = plant.reset()
    for _ in range(400):
        y = plant.step(ctrl.step(10.0, y.speed_a_rad_s), 0.0)
    assert ctrl.estimate_rad_s == pytest.approx(10.0, abs=1e-6)
    assert (abs(y.speed_a_rad_s - 10.0) > 0.5) == static_error
    if not static_error:
        assert estimator.state[-1] == pytest.approx(-0.8, abs=1e-6)


# -- accuracy on the physics simulator ----------------------------------------------------------

TICKS = 3000
_t = np.arange(TICKS) * 0.01
SLOW_MULTISINE_V = (
    4.0
    + 1.5 * np.sin(2 * np.pi * 0.5 * _t)
    + 1.0 * np.sin(2 * np.pi * 1.3 * _t + 1.0)
    + 0.5 * np.sin(2 * np.pi * 3.1 * _t + 2.0)
)
SMALL_STEPS_V = 2.5 + 0.5 * np.sign(np.sin(2 * np.pi * 0.5 * _t + 0.1))
REFERENCE_STEPS_RAD_S = np.repeat([5.0, 10.0, 15.0, 10.0, 3.0, 8.0], 100)


def physics_run(design: KalmanDesign, voltage_v=None, reference_rad_s=None, controllers=None):
    """Run motor A of the physics cart open loop (voltages) or closed loop (references).

    Returns the estimate x̂_1[k|k], the measured speed and the true speed at each tick (rad/s).
    """
    est = SteadyStateSpeedEstimator(design)
    plant = PhysicsPlant("ground")
    y = plant.reset(position_rad=(0.001, 0.0))
    seq = voltage_v if voltage_v is not None else reference_rad_s
    out = np.zeros((3, len(seq)))
    for k, value in enumerate(seq):
        out[:, k] = est.correct(y.speed_a_rad_s), y.speed_a_rad_s, y.true_speed_a_rad_s
        if controllers is None:
            ua, ub = float(value), 0.0
        else:
            ua = controllers[0].step(value, y.speed_a_rad_s)
            ub = controllers[1].step(value, y.speed_b_rad_s)
        est.predict(ua)
        y = plant.step(ua, ub)
    return out


def accuracy(estimate, measured, true, skip: int = 100) -> tuple[float, float, float]:
    """RMS errors (rad/s) of the estimate and of the measurement against the half-tick-earlier
    true speed, and the lag (ticks) that best aligns the estimate with the instantaneous one."""
    half = np.r_[true[0], 0.5 * (true[1:] + true[:-1])]
    s = slice(skip, None)

    def rms(a, b):
        return float(np.sqrt(np.mean((a[s] - b[s]) ** 2)))

    k = np.arange(true.size)
    shifts = np.arange(-2.0, 2.0001, 0.05)
    lag = shifts[np.argmin([rms(estimate, np.interp(k - sh, k, true)) for sh in shifts])]
    return rms(estimate, half), rms(measured, half), float(lag)


@pytest.fixture(scope="module")
def physics_model() -> ArxModel:
    """Motor A of the physics cart, identified as the report did but by output error.

    Random ±2.5 V steps around 6 V (held 3–10 ticks, no zero crossing), deviations from the
    means (the friction offset is the estimator's bias state's job), two poles and two zeros.
    The command lands 3 ms into its tick, so the next speed sample already sees most of it: the
    delay that simulates this plant best is one tick (nk = 1), not the report's two.
    """
    rng = np.random.default_rng(1)
    u = np.empty(4000)
    k = 0
    while k < u.size:
        hold = int(rng.integers(3, 11))
        u[k : k + hold] = 6.0 + rng.choice([-2.5, 2.5])
        k += hold
    trace = run_experiment(PhysicsPlant("ground"), u, u).trace
    y, v = trace.speed("a")[200:], trace.voltage("a")[200:]
    data = [(y - y.mean(), v - v.mean())]
    return fit_oe(data, fit_arx(data, na=2, nb=2, nk=1).model).model


def test_identified_model_predicts_the_simulator(physics_model: ArxModel) -> None:
    """The estimator of these accuracy tests is designed on a model of the simulator itself (the
    report's own model is judged on the shipped controller): it simulates fresh data of the same
    kind to better than 90 % (NRMSE fit)."""
    rng = np.random.default_rng(2)
    u = 6.0 + 2.5 * rng.choice([-1.0, 1.0], size=1500).repeat(2)[:1500]
    trace = run_experiment(PhysicsPlant("ground"), u, u).trace
    y, v = trace.speed("a")[200:], trace.voltage("a")[200:]
    y, v = y - y.mean(), v - v.mean()
    fit = 1.0 - np.linalg.norm(y - physics_model.simulate(v)) / np.linalg.norm(y)
    assert fit > 0.9
    assert physics_model.dc_gain() == pytest.approx(2.2, abs=0.15)


@pytest.mark.parametrize("scenario", ["slow multisine", "closed loop steps"])
def test_estimate_halves_the_quantisation_error(physics_model, ground, scenario) -> None:
    design = design_kalman(physics_model)
    if scenario == "slow multisine":
        run = physics_run(design, voltage_v=SLOW_MULTISINE_V)
    else:
        controllers = [
            StateFeedbackController(
                design_poles(m, settling_time_s=0.06, overshoot_percent=1.0, extra_delay_ticks=1)
            )
            for m in ground
        ]
        run = physics_run(design, reference_rad_s=REFERENCE_STEPS_RAD_S, controllers=controllers)
    rms_estimate, rms_measured, lag = accuracy(*run)
    assert rms_measured == pytest.approx(quantisation_std_rad_s(0.01), rel=0.15)
    assert rms_estimate <= 0.5 * rms_measured
    assert 0.0 <= lag <= 1.0


def test_report_model_estimate_when_quantisation_dominates() -> None:
    """On the report's own model the estimate halves the error where the speed changes slowly
    (small steps at 3–5 rad/s); with fast transients its model error limits it (see the reply)."""
    rms_estimate, rms_measured, lag = accuracy(
        *physics_run(design_kalman(REPORT_A), voltage_v=SMALL_STEPS_V)
    )
    assert rms_estimate <= 0.5 * rms_measured
    assert 0.0 <= lag <= 1.0
