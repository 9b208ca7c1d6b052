"""Pole placement: the realisation, the placed poles (python-control), rejections, the closed loop."""

from __future__ import annotations

import functools
import json
import math
import tomllib
from pathlib import Path

import control
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.data.modelfile import load_models
from cartctl.design.analysis import settling_bound
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.design.kalman import realise
from cartctl.design.poles import augment, design_poles, spec_poles
from cartctl.errors import InputError
from cartctl.measures.stepinfo import step_info
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.kalman import KalmanSpeedEstimator
from cartctl.runtime.statefeedback import StateFeedbackController

# The designs of the shipped controllers/poles.toml (on board, loop delay 1) and
# controllers/serial-poles.toml (through the PC serial loop, loop delay 3).
RECOMMENDED = {"settling_time_s": 0.045, "overshoot_percent": 1.0}
SERIAL = {"settling_time_s": 0.06, "overshoot_percent": 1.0, "extra_delay_ticks": 2}
CONTROLLERS = Path(__file__).resolve().parents[1] / "controllers"
QUANTUM_RAD_S = 2 * math.pi / 1792 / 0.01
"""One encoder count per tick (rad/s)."""


@pytest.fixture
def ground(ground_path) -> tuple[ArxModel, ArxModel]:
    models = load_models(ground_path)
    return models.motor("a"), models.motor("b")


def run_step(
    designs, plant, reference_rad_s: float | np.ndarray, ticks: int = 200, **controller_kw
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed loop in the runtime's tick order; returns time (s), motor-A speed and voltage."""
    refs = np.broadcast_to(np.asarray(reference_rad_s, dtype=float), (ticks,))
    ca, cb = (StateFeedbackController(d, **controller_kw) for d in designs)
    y = plant.reset()
    speed, volts = np.zeros(ticks), np.zeros(ticks)
    for k in range(ticks):
        speed[k] = y.speed_a_rad_s
        ua = ca.step(refs[k], y.speed_a_rad_s)
        ub = cb.step(refs[k], y.speed_b_rad_s)
        volts[k] = ua
        y = plant.step(ua, ub)
    return np.arange(ticks) * plant.period_s, speed, volts


@functools.cache
def nominal_design():
    """The nominal design on the report's ground model A (built once for the property test)."""
    return design_poles(ArxModel((-0.9356, 0.2173), (0.6466, -0.07751)), **RECOMMENDED)


def match(expected, actual) -> float:
    """Largest distance between two multisets of poles, paired greedily nearest-first."""
    left = list(np.asarray(actual, dtype=complex))
    worst = 0.0
    for p in expected:
        i = int(np.argmin([abs(p - q) for q in left]))
        worst = max(worst, abs(p - left.pop(i)))
    return worst


# -- the realisation ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "model",
    [
        ArxModel((-0.9356, 0.2173), (0.6466, -0.07751)),  # the report's ground model A
        ArxModel((-0.5393, 0.0373), (1.081, -0.0323)),  # air model A
        ArxModel((-1.2, 0.5, -0.1), (0.3,), nk=1),  # na = 3, nb = 1, nk = 1
        ArxModel((-0.5,), (0.2, 0.1, 0.05), nk=3),  # na = 1, nb = 3
    ],
)
@pytest.mark.parametrize("extra", [0, 2])
def test_realisation_has_the_models_transfer_function(model: ArxModel, extra: int) -> None:
    plant = realise(model, extra_delay_ticks=extra)
    delayed = ArxModel(model.ar, model.b, model.nk + extra, model.period_s)
    assert plant.order == delayed.order >= model.order
    u = np.random.default_rng(7).normal(size=300)
    np.testing.assert_allclose(plant.simulate(u), delayed.simulate(u), rtol=0, atol=1e-10)
    tf = control.ss2tf(plant.to_control())
    num, den = np.ravel(tf.num[0][0]), np.ravel(tf.den[0][0])
    np.testing.assert_allclose(np.trim_zeros(np.round(num, 12), "f"), delayed.num(), atol=1e-10)
    np.testing.assert_allclose(den, delayed.den(), atol=1e-10)
    assert plant.is_controllable()


def test_realisation_state_means_speed_and_predictions(ground) -> None:
    """x_1 = y, x_2 = y[k+1] + c y[k], x_3 = b u[k−1] for (a z + b) / (z³ + c z² + d z)."""
    model = ground[0]
    (c, d), (a, b) = model.ar, model.b
    plant = realise(model)
    assert plant.order == 3
    np.testing.assert_array_equal(plant.C, [1.0, 0.0, 0.0])
    u = np.random.default_rng(3).normal(size=50)
    y = model.simulate(u)
    x = np.zeros(3)
    for k in range(1, 48):
        x = plant.A @ x + plant.B * u[k - 1]  # x[k]
        assert x[0] == pytest.approx(y[k], abs=1e-12)
        assert x[1] == pytest.approx(y[k + 1] + c * y[k], abs=1e-12)
        assert x[2] == pytest.approx(b * u[k - 1], abs=1e-12)
        if k >= 2:
            assert x[1] == pytest.approx(a * u[k - 1] + b * u[k - 2] - d * y[k - 1], abs=1e-12)


@pytest.mark.parametrize(
    ("model", "extra", "words"),
    [
        (ArxModel((-0.5,), (1.0,), nk=0), 0, "nk >= 1"),
        (ArxModel((-0.5,), (1.0,), nk=1), -1, "extra_delay_ticks"),
        (ArxModel((-0.5,), (1.0,), nk=1), 1.5, "extra_delay_ticks"),
    ],
)
def test_realisation_rejects(model: ArxModel, extra, words: str) -> None:
    with pytest.raises(InputError, match=words):
        realise(model, extra_delay_ticks=extra)


# -- placed poles --------------------------------------------------------------------------------

# (poles, extra delay, placement method): n poles with the disturbance estimate (the default), one
# more for the error integrator without it (bias_drift_std_v=0)
DISTURBANCE_CASES = [
    ([0.6, 0.4, 0.2], 0, "place"),  # distinct real
    ([0.6 + 0.2j, 0.6 - 0.2j, 0.3], 0, "place"),  # a complex pair
    ([0.5, 0.5, 0.3], 0, "acker"),  # a repeated pole
    ([0.6 + 0.2j, 0.6 - 0.2j, 0.3, 0.1], 1, "place"),  # one extra delay tick: 4 poles
    ([0.0, 0.6, 0.5, 0.4, 0.3, 0.2], 3, "place"),  # the serial loop; a pole at the origin is fine
]
INTEGRATOR_CASES = [
    ([0.6, 0.4, 0.2, 0.1], 0, "place"),
    ([0.6 + 0.2j, 0.6 - 0.2j, 0.3, 0.1], 0, "place"),
    ([0.5 + 0.3j, 0.5 - 0.3j, 0.2 + 0.1j, 0.2 - 0.1j], 0, "place"),  # two pairs
    ([0.5, 0.5, 0.3, 0.2], 0, "acker"),
    ([0.7 + 0.1j, 0.7 - 0.1j, 0.3, 0.3], 0, "acker"),  # a pair and a repeated real pole
    ([0.6 + 0.2j, 0.6 - 0.2j, 0.3, 0.2, 0.1], 1, "place"),
    ([0.0, 0.6, 0.5, 0.4, 0.3, 0.2], 2, "place"),
]


@pytest.mark.parametrize(("poles", "extra", "method"), DISTURBANCE_CASES)
def test_placed_poles_with_the_disturbance_estimate(ground, poles, extra, method) -> None:
    design = design_poles(ground[0], poles=poles, extra_delay_ticks=extra)
    n = design.plant.order
    assert design.integral == "disturbance" and design.method == method
    assert len(design.poles) == len(poles) == n
    # A − B K[:n] from the realisation's matrices: its eigenvalues are the requested poles
    a_cl = design.plant.A - np.outer(design.plant.B, design.K[:n])
    assert match(poles, np.linalg.eigvals(a_cl)) < 1e-6
    # the gain covers the estimator's state: 1 V per V on the disturbance estimate, no integrator
    assert design.estimator.has_bias and design.K.shape == (n + 1,) and design.K[n] == 1.0
    assert design.Ki == 0.0
    # Kr gives the model's loop r → y unit DC gain: C (I − A + B K)⁻¹ B Kr = 1
    dc = design.plant.C @ np.linalg.solve(np.eye(n) - a_cl, design.plant.B)
    assert dc * design.Kr == pytest.approx(1.0)


@pytest.mark.parametrize(("poles", "extra", "method"), INTEGRATOR_CASES)
def test_placed_poles_with_the_error_integrator(ground, poles, extra, method) -> None:
    design = design_poles(ground[0], poles=poles, extra_delay_ticks=extra, bias_drift_std_v=0.0)
    assert design.integral == "error" and design.method == method
    assert len(design.poles) == len(poles) == design.plant.order + 1
    assert match(poles, np.linalg.eigvals(design.closed_loop_matrix())) < 1e-6
    assert design.K.shape == (design.plant.order,)
    assert not design.estimator.has_bias
    assert design.Ki < 0.0  # a wheel behind (r > y) raises the voltage


@pytest.mark.parametrize(("bias", "count"), [(0.0, 4), (0.03, 3)])
def test_manifold_pole_by_ackermann(ground, bias: float, count: int) -> None:
    """Eigenvalues of a k-fold pole are only good to ε^(1/k); the polynomial is exact."""
    design = design_poles(ground[0], poles=[0.4] * count, bias_drift_std_v=bias)
    assert design.method == "acker"
    a_cl = design.closed_loop_matrix()
    np.testing.assert_allclose(np.poly(a_cl), np.poly([0.4] * count), atol=1e-9)
    assert match([0.4] * count, np.linalg.eigvals(a_cl)) < 1e-3


def test_gains_agree_with_python_control(ground) -> None:
    poles = [0.6 + 0.2j, 0.6 - 0.2j, 0.3]
    design = design_poles(ground[1], poles=poles)
    plant = realise(ground[1])
    expected = np.ravel(control.place(plant.A, plant.B.reshape(-1, 1), poles))
    np.testing.assert_allclose(design.K[:3], expected, rtol=1e-9)
    integrator = design_poles(ground[1], poles=[*poles, 0.1], bias_drift_std_v=0.0)
    A_a, B_a = augment(integrator.plant)
    expected = np.ravel(control.place(A_a, B_a.reshape(-1, 1), [*poles, 0.1]))
    np.testing.assert_allclose(np.append(integrator.K, integrator.Ki), expected, rtol=1e-9)


@pytest.mark.parametrize(("bias", "fast"), [(0.03, [4]), (0.0, [5, 4])])
def test_specification_gives_the_dominant_pair(ground, bias: float, fast: list[int]) -> None:
    design = design_poles(
        ground[0], settling_time_s=0.1, overshoot_percent=5.0, bias_drift_std_v=bias
    )
    ts = design.period_s
    pair = [p for p in design.poles if p.imag > 0]
    assert len(pair) == 1
    s = complex(math.log(abs(pair[0])), math.atan2(pair[0].imag, pair[0].real)) / ts
    zeta = -s.real / abs(s)
    assert -s.real == pytest.approx(4.0 / 0.1)  # ζ ω_n from the 2 % settling time
    assert 100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)) == pytest.approx(5.0)
    real = sorted(p.real for p in design.poles if p.imag == 0)
    assert real == pytest.approx([math.exp(-r * 40 * ts) for r in fast])
    assert design.method == "place"
    assert match(design.poles, np.linalg.eigvals(design.closed_loop_matrix())) < 1e-6


def test_specification_with_extra_delay_places_more_fast_poles(ground) -> None:
    design = design_poles(
        ground[0], settling_time_s=0.1, overshoot_percent=5.0, extra_delay_ticks=2
    )
    assert len(design.poles) == 5
    assert sum(p.imag == 0 for p in design.poles) == 3
    assert match(design.poles, np.linalg.eigvals(design.closed_loop_matrix())) < 1e-6


def _controller_ss(K, Ki, A, B, C, L, ts):
    """The runtime's control law from y to u (r = 0) as a python-control system.

    Per tick: x̂c = x̂ + L (y − C x̂), u = −K x̂c − Ki x_i, x̂⁺ = A x̂c + B u, x_i⁺ = x_i − Ts y;
    state [x̂, x_i], the gains K on the first K.size states of x̂.
    """
    m = A.shape[0]
    k = np.zeros(m)
    k[: K.size] = K
    lc = np.eye(m) - np.outer(L, C)
    a = np.zeros((m + 1, m + 1))
    a[:m, :m] = A @ lc - np.outer(B, k @ lc)
    a[:m, m] = -B * Ki
    a[m, m] = 1.0
    b = np.r_[A @ L - B * (k @ L), -ts].reshape(-1, 1)
    c = np.r_[-(k @ lc), -Ki].reshape(1, -1)
    d = [[-(k @ L)]]
    return control.ss(a, b, c, d, ts)


def _check_every_pole_is_placed(theta, nk, extra, K, Ki, Kr, est, placed, runtime) -> None:
    """The closed loop of the plant (with its whole delay) and the controller has, as poles, the
    placed ones, the estimator's, and z = 1 for an integrator that does not act (Ki = 0)."""
    ar, num = np.asarray(theta[:2]), np.asarray(theta[2:])  # na = 2: [c, d], then the b's
    ts = 0.01
    delay = nk + extra  # the loop's whole input delay, in ticks
    plant = control.tf(  # Σ b_i z^−(delay+i) / (1 + c z^−1 + d z^−2), in powers of z
        num, np.polymul(np.r_[1.0, ar], np.r_[1.0, np.zeros(delay + num.size - 1 - ar.size)]), ts
    )  # (a z + b) / (z² + c z + d) · z^−(delay − 1)
    A, B, C, L = (np.asarray(est[k], dtype=float) for k in ("A", "B", "C", "L"))
    ctrl = _controller_ss(np.asarray(K, dtype=float), Ki, A, B, C, L, ts)
    loop = control.feedback(control.ss(plant), -ctrl, sign=-1)  # u = C_ss(y): positive feedback
    got = np.linalg.eigvals(loop.A)
    filt = np.linalg.eigvals((np.eye(A.shape[0]) - np.outer(L, C)) @ A)
    expected = [complex(*p) if isinstance(p, list) else complex(p) for p in placed]
    expected += list(filt) + ([1.0] if Ki == 0.0 else [])
    assert len(got) == len(expected)
    # the estimator's delay states give a multiple pole at 0, whose eigenvalues are only good to
    # ε^(1/k): compare the characteristic polynomials, the roots loosely
    np.testing.assert_allclose(np.poly(loop.A), np.real(np.poly(expected)), atol=1e-9)
    assert match(expected, got) < 1e-3
    assert all(abs(p) < 1.0 for p in expected if p != 1.0)
    # the runtime controller is that control law: the same voltages for the same measurements
    y = np.random.default_rng(4).normal(0.0, 0.5, 60)
    u_ss = np.ravel(control.forced_response(ctrl, U=y).outputs)
    runtime.reset()
    np.testing.assert_allclose([runtime.step(0.0, float(v)) for v in y], u_ss, atol=1e-9)


def test_the_serial_design_places_every_closed_loop_pole(ground) -> None:
    model = ground[0]
    design = design_poles(model, **SERIAL)
    assert design.plant.order == 5 and len(design.poles) == 5  # 3 + 2 delay states
    est = {k: getattr(design.estimator, k) for k in ("A", "B", "C", "L")}
    _check_every_pole_is_placed(
        (*model.ar, *model.b), model.nk, 2, design.K, design.Ki, design.Kr, est,
        list(design.poles), StateFeedbackController(design),
    )  # fmt: skip


@pytest.mark.parametrize("name", ["serial-poles.toml", "poles.toml"])
def test_shipped_design_places_every_closed_loop_pole(ground_path, name: str) -> None:
    """The shipped file's own numbers, against the plant with the loop delay the file is for."""
    controller = load_controller(CONTROLLERS / name)
    if controller.request.get("timing_noise_std_ticks"):
        # the control law with the steady-state gain L, which poles.toml's time-varying gain
        # (moved by each command change) returns to: the linear loop checked here
        from cartctl.export.arduino import as_steady_state

        controller = as_steady_state(controller)
    runtime = build_controllers(controller)
    raw = tomllib.loads((CONTROLLERS / name).read_text(encoding="utf-8"))
    models = load_models(controller.model_path)  # the model it was designed on
    for motor, entry in raw["motors"].items():
        model = models.motor(motor)
        extra = int(controller.request["extra_delay_ticks"])
        assert extra == (2 if name.startswith("serial") else 0)
        _check_every_pole_is_placed(
            (*model.ar, *model.b), model.nk, extra, entry["K"], entry["Ki"], entry["Kr"],
            entry["estimator"], entry["closed_loop_poles"], runtime[motor],
        )  # fmt: skip


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"poles": [1.0, 0.5, 0.3]}, "unit circle"),
        ({"poles": [0.5, -1.2, 0.3]}, "unit circle"),
        ({"poles": [0.9j, -0.9j, 0.2j]}, "conjugate"),
        ({"poles": [0.5 + 0.1j, 0.5 + 0.1j, 0.3]}, "conjugate"),
        ({"poles": [0.5, 0.3, 0.2, 0.1]}, "needs 3 closed-loop poles, got 4"),
        ({"poles": [0.5, 0.3, 0.2], "bias_drift_std_v": 0.0}, "needs 4 closed-loop poles, got 3"),
        ({"poles": [0.5, 0.4, 0.3], "extra_delay_ticks": 1}, "needs 4 closed-loop poles"),
        ({"poles": [math.nan, 0.4, 0.3]}, "finite"),
        ({}, "either poles or both"),
        ({"poles": [0.5] * 3, "settling_time_s": 0.1, "overshoot_percent": 5}, "either poles"),
        ({"settling_time_s": 0.1}, "either poles or both"),
        ({"settling_time_s": 0.1, "overshoot_percent": 0.0}, "overshoot_percent"),
        ({"settling_time_s": 0.1, "overshoot_percent": 100.0}, "overshoot_percent"),
        ({"settling_time_s": 0.1, "overshoot_percent": -3.0}, "overshoot_percent"),
        ({"settling_time_s": 0.02, "overshoot_percent": 5.0}, "at least 3 ticks"),
        ({"settling_time_s": 0.03, "overshoot_percent": 5.0, "bias_drift_std_v": 0}, "4 ticks"),
        ({"settling_time_s": 0.03, "overshoot_percent": 5, "extra_delay_ticks": 1}, "4 ticks"),
        ({"settling_time_s": 0.1, "overshoot_percent": 5.0, "fast_pole_ratio": 0.5}, "ratio"),
        ({"settling_time_s": 0.05, "overshoot_percent": 99.0}, "Nyquist"),
        ({"settling_time_s": 0.1, "overshoot_percent": 5.0, "bias_drift_std_v": -1}, "bias"),
    ],
)
def test_rejections(ground, kwargs, words) -> None:
    with pytest.raises(InputError, match=words):
        design_poles(ground[0], **kwargs)


@pytest.mark.parametrize(
    "model",
    [
        ArxModel.from_tf([1.0, -0.5], [1.0, -0.8, 0.15, 0.0]),  # zero at 0.5 cancels a pole
        ArxModel.from_tf([1.0, -1.0], [1.0, -0.9, 0.2, 0.0]),  # zero at z = 1 blocks the integrator
    ],
)
@pytest.mark.parametrize("bias", [0.0, 0.03])
def test_uncontrollable_models_are_rejected(model: ArxModel, bias: float) -> None:
    with pytest.raises(InputError, match="cannot be controlled"):
        design_poles(model, settling_time_s=0.1, overshoot_percent=5.0, bias_drift_std_v=bias)


def test_to_dict_is_json(ground) -> None:
    design = design_poles(ground[0], **SERIAL)
    out = json.loads(json.dumps(design.to_dict()))
    assert out["method"] == "poles" and out["integral_action"] == "disturbance"
    assert len(out["closed_loop_poles"]) == 5
    assert len(out["estimator_poles"]) == design.estimator.A.shape[0] == 6
    assert out["Ki"] == 0.0 and len(out["K"]) == 6


# -- closed loop -------------------------------------------------------------------------------


def settling_band(step_rad_s: float) -> float:
    """The settling band of the issue, as a fraction of the step: max(2 %, one count per tick)."""
    return max(0.02, QUANTUM_RAD_S / abs(step_rad_s))


@pytest.mark.parametrize(
    ("spec", "extra", "limit_s"),
    [(RECOMMENDED, 0, 0.09), (SERIAL, 2, None)],
    ids=["on-board", "serial"],
)
def test_ten_rad_s_step_on_the_loop_it_is_designed_for(ground, spec, extra, limit_s) -> None:
    """On board: ≤ 5 % and ≤ 90 ms; through the serial loop: ≤ 5 % and ≤ 3× the time-optimal
    settling for the same loop delay (the model with nk + 2)."""
    designs = [design_poles(m, **spec) for m in ground]
    plant_models = [ArxModel(m.ar, m.b, m.nk + extra) for m in ground]
    t, y, u = run_step(designs, ArxPlant(*plant_models), 10.0)
    info = step_info(t, y, reference=10.0, settling_band=settling_band(10.0))
    if limit_s is None:
        limit_s = 3.0 * settling_bound(plant_models[0], 10.0).settling_time_s
    assert info.overshoot_percent <= 5.0
    assert info.settling_time_s is not None and info.settling_time_s <= limit_s
    assert abs(y[-20:] - 10.0).max() < 1e-9  # no steady-state error
    assert np.abs(u).max() <= 12.0


def test_a_plant_a_tick_late_stays_tame(ground) -> None:
    """The disturbance estimate as integral action keeps the margins of the model-based loop:
    one tick more delay than designed overshoots half as much as with the error integrator."""
    late = ArxPlant(*(ArxModel(m.ar, m.b, m.nk + 1) for m in ground))
    overshoot = {}
    for bias in (0.03, 0.0):
        designs = [design_poles(m, **RECOMMENDED, bias_drift_std_v=bias) for m in ground]
        t, y, _ = run_step(designs, late, 10.0)
        info = step_info(t, y, reference=10.0, settling_band=settling_band(10.0))
        assert info.settling_time_s is not None and info.settling_time_s < 0.3
        overshoot[bias] = info.overshoot_percent
    assert overshoot[0.03] <= 25.0 and overshoot[0.0] >= 1.5 * overshoot[0.03]


@pytest.mark.parametrize("step", [(0.0, 22.0), (20.0, -20.0)])
@pytest.mark.parametrize("bias", [0.03, 0.0])
def test_saturated_steps_do_not_wind_up(ground, step, bias) -> None:
    designs = [design_poles(m, **RECOMMENDED, bias_drift_std_v=bias) for m in ground]
    refs = np.r_[np.full(100, step[0]), np.full(200, step[1])]
    t, y, u = run_step(designs, ArxPlant(*ground), refs, ticks=300)
    assert np.abs(u).max() == 12.0  # it does saturate
    info = step_info(t[100:], y[100:], reference=step[1], initial=y[99], onset_s=t[100])
    assert info.overshoot_percent <= 5.0
    assert abs(y[-20:] - step[1]).max() < 1e-9


class OffsetPlant(ArxPlant):
    """The ARX cart with a constant voltage lost on the way, as dry friction takes it (V)."""

    def __init__(self, models, offset_v: float) -> None:
        super().__init__(*models)
        self.offset_v = offset_v

    def step(self, voltage_a_v: float, voltage_b_v: float):
        return super().step(voltage_a_v - self.offset_v, voltage_b_v - self.offset_v)


@pytest.mark.parametrize("bias", [0.03, 0.0])
def test_integral_action_removes_the_static_error_of_a_wrong_model(ground, bias) -> None:
    model = ground[0]
    slower = ArxModel(model.ar, tuple(0.8 * v for v in model.b), model.nk)  # 20 % less gain
    designs = [design_poles(model, **RECOMMENDED, bias_drift_std_v=bias)] * 2
    _, y, _ = run_step(designs, ArxPlant(slower, slower), 10.0, ticks=300)
    assert abs(y[-20:] - 10.0).max() < 1e-6
    _, y, _ = run_step(designs, OffsetPlant(ground, 0.8), 10.0, ticks=300)
    assert abs(y[-20:] - 10.0).max() < 1e-6


def test_the_disturbance_estimate_is_the_lost_voltage(ground) -> None:
    """b̂ converges to the voltage the plant loses, and the speed estimate has no offset."""
    design = design_poles(ground[0], **RECOMMENDED)
    ctrl = StateFeedbackController(design)
    plant = OffsetPlant(ground, 0.8)
    y = plant.reset()
    for _ in range(300):
        y = plant.step(ctrl.step(10.0, y.speed_a_rad_s), 0.0)
    assert ctrl.estimator.state[-1] == pytest.approx(-0.8, abs=1e-6)
    assert ctrl.estimate_rad_s == pytest.approx(10.0, abs=1e-6)


def test_feedforward_advances_the_response_by_one_tick(ground) -> None:
    """Error integrator: Kr = −Ki Ts puts the reference zero at z = 0: the same response, one
    tick sooner."""
    plain = [
        design_poles(m, **RECOMMENDED, reference_feedforward=False, bias_drift_std_v=0.0)
        for m in ground
    ]
    fed = [design_poles(m, **RECOMMENDED, bias_drift_std_v=0.0) for m in ground]
    assert plain[0].Kr == 0.0
    _, y0, u0 = run_step(plain, ArxPlant(*ground), 10.0)
    _, y1, u1 = run_step(fed, ArxPlant(*ground), 10.0)
    np.testing.assert_allclose(y1[:-1], y0[1:], atol=1e-9)
    np.testing.assert_allclose(u1[:-1], u0[1:], atol=1e-9)


def test_controller_with_the_propagated_estimator(ground) -> None:
    designs = [design_poles(m, **RECOMMENDED) for m in ground]
    ca, cb = (
        StateFeedbackController(d, estimator=KalmanSpeedEstimator(d.estimator)) for d in designs
    )
    plant = ArxPlant(*ground)
    y = plant.reset()
    for _ in range(200):
        y = plant.step(ca.step(10.0, y.speed_a_rad_s), cb.step(10.0, y.speed_b_rad_s))
    assert y.speed_a_rad_s == pytest.approx(10.0, abs=1e-6)
    assert ca.estimate_rad_s == pytest.approx(10.0, abs=1e-6)


def test_non_finite_inputs_give_zero_volts(ground) -> None:
    design = design_poles(ground[0], **RECOMMENDED)
    ctrl = StateFeedbackController(design)
    ctrl.step(10.0, 0.0)
    held = ctrl.integral_rad
    assert ctrl.step(math.nan, 1.0) == 0.0
    assert ctrl.step(10.0, math.inf) == 0.0
    assert ctrl.integral_rad == held
    assert np.all(np.isfinite(ctrl.estimator.state))
    assert 0.0 < ctrl.step(10.0, 1.0) <= 12.0


@pytest.mark.parametrize("limit", [0.0, -1.0, 12.5, math.nan])
def test_voltage_limit_is_checked(ground, limit) -> None:
    with pytest.raises(InputError, match="voltage_limit_v"):
        StateFeedbackController(design_poles(ground[0], **RECOMMENDED), voltage_limit_v=limit)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(allow_nan=True, allow_infinity=True),
            st.floats(allow_nan=True, allow_infinity=True),
        ),
        min_size=1,
        max_size=40,
    ),
    st.floats(0.5, 12.0),
)
def test_voltage_never_leaves_the_limit(steps, limit) -> None:
    ctrl = StateFeedbackController(nominal_design(), voltage_limit_v=limit)
    for reference, measured in steps:
        u = ctrl.step(reference, measured)
        assert math.isfinite(u) and abs(u) <= limit


def test_spec_poles_count() -> None:
    poles = spec_poles(6, 0.01, 0.2, 4.0, 4.0)
    assert len(poles) == 6 and all(abs(p) < 1 for p in poles)
