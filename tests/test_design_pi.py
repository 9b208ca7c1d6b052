"""PI design and the runtime PI: margins checked independently, refusals, C(z) equality, windup."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import control
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import signal

from cartctl.data.modelfile import load_models
from cartctl.design.pi import PiDesign, crossover_range, design_pi, design_pi_bandwidth
from cartctl.errors import InputError
from cartctl.measures.stepinfo import step_info
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.base import Controller
from cartctl.runtime.pi import PiController

GROUND = load_models(Path(__file__).resolve().parents[1] / "models" / "ground.toml")
MOTORS = {name: GROUND.motor(name) for name in ("a", "b")}
TS = 0.01
MODES = ("none", "conditional", "back-calculation")

# (phase margin °, crossover Hz, extra delay ticks), all feasible on both ground motors
REQUESTS = [
    (60.0, 3.0, 0),
    (60.0, 4.0, 0),
    (60.0, 6.0, 0),
    (45.0, 5.0, 0),
    (45.0, 8.0, 0),
    (70.0, 2.5, 0),
    (65.0, 4.4, 0),
    (60.0, 2.0, 2),
    (60.0, 3.0, 2),
    (60.0, 4.0, 2),
    (45.0, 3.0, 2),
]

# The recommended "good 10 rad/s step" settings (shipped as controllers/pi.toml).
RECOMMENDED = {"phase_margin_deg": 65.0, "crossover_hz": 4.4}


def independent_margins(
    design: PiDesign, model: ArxModel, *, default_method: bool = False
) -> tuple[float, float, float]:
    """(gm, pm °, crossover Hz) by python-control from the coefficients alone.

    ``control.margin`` as it comes, or ``stability_margins`` with the exact polynomial method
    (margin's default falls back to a frequency grid for some low crossovers, with a warning).
    """
    plant = control.tf(model.num(), model.den(), dt=TS)
    pi = control.tf(*design.controller_tf_coeffs(), dt=TS)
    delay = control.tf([1.0], [1.0] + [0.0] * design.extra_delay_ticks, dt=TS)
    loop = control.series(pi, plant, delay)
    with warnings.catch_warnings():  # the margins may evaluate L at its integrator pole z = 1
        warnings.simplefilter("ignore", RuntimeWarning)
        if default_method:
            gm, pm, _, wcp = control.margin(loop)
        else:
            gm, pm, _, _, wcp, _ = control.stability_margins(loop, method="poly")
    return gm, pm, wcp / (2.0 * math.pi)


def run_loop(
    controller: Controller,
    model: ArxModel,
    reference_rad_s: np.ndarray,
    limit_v: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed loop on the ARX plant in the tick order of runtime/base.py: (speed, voltage)."""
    plant = ArxPlant(model, model)
    controller.reset()
    y = plant.reset().speed_a_rad_s
    speed, voltage = np.zeros(reference_rad_s.size), np.zeros(reference_rad_s.size)
    for k, r in enumerate(reference_rad_s):
        if limit_v is not None:
            controller.voltage_limit_v = float(limit_v[k])
        u = controller.step(float(r), y)
        speed[k], voltage[k] = y, u
        y = plant.step(u, 0.0).speed_a_rad_s
    return speed, voltage


def pi_for(design: PiDesign, **kwargs: object) -> PiController:
    return PiController(design.kp, design.ki, design.period_s, **kwargs)  # type: ignore[arg-type]


# -- design ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("motor", MOTORS)
@pytest.mark.parametrize(("pm", "fc", "extra"), REQUESTS)
def test_margins_match_request_independently(motor: str, pm: float, fc: float, extra: int) -> None:
    model = MOTORS[motor]
    design = design_pi(model, phase_margin_deg=pm, crossover_hz=fc, extra_delay_ticks=extra)
    assert design.kp >= 0.0
    assert design.ki > 0.0
    gm, pm_got, fc_got = independent_margins(design, model, default_method=True)
    assert pm_got == pytest.approx(pm, abs=1.0)
    assert fc_got == pytest.approx(fc, rel=0.02)
    assert gm > 1.0
    assert independent_margins(design, model) == pytest.approx((gm, pm_got, fc_got))
    analysis = design.analysis()
    assert analysis["phase_margin_deg"] == pytest.approx(pm, abs=1.0)
    assert analysis["crossover_hz"] == pytest.approx(fc, rel=0.02)
    assert analysis["gain_margin_db"] == pytest.approx(20.0 * math.log10(gm))
    assert all(math.hypot(re, im) < 1.0 for re, im in analysis["closed_loop_poles"])
    assert analysis["sensitivity_peak"] >= 1.0
    assert analysis["sensitivity_peak_db"] == pytest.approx(
        20.0 * math.log10(analysis["sensitivity_peak"])
    )


def test_controller_coefficients_are_the_backward_euler_pi() -> None:
    design = design_pi(MOTORS["a"], phase_margin_deg=60.0, crossover_hz=4.0)
    num, den = design.controller_tf_coeffs()
    np.testing.assert_allclose(num, [design.kp + design.ki * TS, -design.kp])
    np.testing.assert_array_equal(den, [1.0, -1.0])
    # C(z) = Kp + Ki·Ts·z/(z − 1) at a point on the unit circle
    z = np.exp(0.3j)
    assert np.polyval(num, z) / np.polyval(den, z) == pytest.approx(
        design.kp + design.ki * TS * z / (z - 1.0)
    )


def test_open_and_closed_loop_agree() -> None:
    design = design_pi(MOTORS["b"], phase_margin_deg=60.0, crossover_hz=3.0, extra_delay_ticks=2)
    z = np.exp(2j * np.pi * np.array([0.5, 3.0, 20.0]) * TS)
    loop = design.open_loop()(z)
    np.testing.assert_allclose(design.closed_loop()(z), loop / (1.0 + loop))
    assert abs(loop[1]) == pytest.approx(1.0)
    assert design.closed_loop().dcgain() == pytest.approx(1.0)
    doc = design.to_dict()
    assert doc["controller_den"] == [1.0, -1.0]
    assert {"kp", "ki", "controller_num", "phase_margin_deg", "closed_loop_poles"} <= set(doc)


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"phase_margin_deg": 60.0, "crossover_hz": 2.0}, r"Kp = -.* < 0.*crossover must lie"),
        ({"phase_margin_deg": 60.0, "crossover_hz": 12.0}, r"Ki = .* <= 0.*crossover must lie"),
        ({"phase_margin_deg": 45.0, "crossover_hz": 3.0}, r"45° .* 3 Hz.*crossover must lie"),
        ({"phase_margin_deg": 0.0, "crossover_hz": 4.0}, r"phase margin .*\(0, 89\].* 0\.0"),
        ({"phase_margin_deg": 90.0, "crossover_hz": 4.0}, r"phase margin .*got 90"),
        ({"phase_margin_deg": math.nan, "crossover_hz": 4.0}, r"phase margin .*nan"),
        ({"phase_margin_deg": 60.0, "crossover_hz": 0.0}, r"crossover .*\(0, 50\) Hz.*got 0"),
        ({"phase_margin_deg": 60.0, "crossover_hz": 50.0}, r"below Nyquist.*got 50"),
        ({"phase_margin_deg": 60.0, "crossover_hz": 4.0, "extra_delay_ticks": -1}, r"extra delay"),
        ({"phase_margin_deg": 60.0, "crossover_hz": 4.0, "extra_delay_ticks": 1.5}, r"whole"),
    ],
)
def test_impossible_requests_are_refused_with_useful_text(
    kwargs: dict[str, float], expected: str
) -> None:
    with pytest.raises(InputError, match=expected):
        design_pi(MOTORS["a"], **kwargs)  # type: ignore[arg-type]


def _feasible_band_hz(model: ArxModel, pm_deg: float) -> tuple[float, float]:
    """Where a PI can give ``pm_deg``, from python-control's frequency response of the model.

    The PI C = Kp + Ki·Ts·z/(z − 1) has a phase between its integral part's, −90° + ωTs/2, and
    0°; at the crossover it must supply −180° + PM − ∠G. Both ends of the band, on a fine grid.
    """
    f = np.linspace(0.2, 49.0, 200_001)
    z = np.exp(1j * 2 * np.pi * f * model.period_s)
    plant_deg = np.degrees(np.unwrap(np.angle(model.to_tf()(z))))
    integral_deg = np.degrees(np.angle(z / (z - 1.0)))
    needed = -180.0 + pm_deg - plant_deg
    ok = np.flatnonzero((needed < 0.0) & (needed > integral_deg))
    return float(f[ok[0]]), float(f[ok[-1]])


@pytest.mark.parametrize(("pm", "fc"), [(60.0, 2.0), (60.0, 12.0), (45.0, 3.0)])
def test_a_refusal_states_the_band_python_control_finds(pm: float, fc: float) -> None:
    lo, hi = _feasible_band_hz(MOTORS["a"], pm)
    with pytest.raises(InputError) as refused:
        design_pi(MOTORS["a"], phase_margin_deg=pm, crossover_hz=fc)
    stated = [
        float(x) for x in re.findall(r"between ([\d.]+) Hz and ([\d.]+) Hz", str(refused.value))[0]
    ]
    assert stated == pytest.approx([lo, hi], abs=0.011)
    assert not lo <= fc <= hi


def test_unstable_model_is_refused() -> None:
    unstable = ArxModel.from_theta([-1.5, 0.2, 0.6, 0.0])
    with pytest.raises(InputError, match="unstable"):
        design_pi(unstable, phase_margin_deg=60.0, crossover_hz=4.0)


@pytest.mark.parametrize("motor", MOTORS)
@pytest.mark.parametrize(("pm", "extra"), [(45.0, 0), (60.0, 0), (60.0, 2), (80.0, 1)])
def test_the_stated_crossover_range_works_at_its_edges(motor: str, pm: float, extra: int) -> None:
    model = MOTORS[motor]
    span = crossover_range(model, phase_margin_deg=pm, extra_delay_ticks=extra)
    assert span is not None
    low, high = span
    for fc in (low * 1.0001, 0.5 * (low + high), high * 0.9999):
        design_pi(model, phase_margin_deg=pm, crossover_hz=fc, extra_delay_ticks=extra)
    for fc in (low * 0.99, high * 1.01):
        with pytest.raises(InputError, match="cannot give"):
            design_pi(model, phase_margin_deg=pm, crossover_hz=fc, extra_delay_ticks=extra)


@settings(max_examples=15, deadline=None)  # each designs a PI and checks it (~60 ms)
@given(
    st.floats(min_value=20.0, max_value=85.0),
    st.floats(min_value=0.5, max_value=15.0),
    st.integers(min_value=0, max_value=3),
)
def test_a_design_is_stable_and_meets_its_margin_or_is_refused(
    pm: float, fc: float, extra: int
) -> None:
    model = MOTORS["a"]
    span = crossover_range(model, phase_margin_deg=pm, extra_delay_ticks=extra)
    assert span is not None
    assume(abs(fc - span[0]) > 1e-4 * fc and abs(fc - span[1]) > 1e-4 * fc)
    if not span[0] < fc < span[1]:
        with pytest.raises(InputError, match="cannot give"):
            design_pi(model, phase_margin_deg=pm, crossover_hz=fc, extra_delay_ticks=extra)
        return
    design = design_pi(model, phase_margin_deg=pm, crossover_hz=fc, extra_delay_ticks=extra)
    poles = control.feedback(design.open_loop(), 1).poles()
    assert np.all(np.abs(poles) < 1.0)
    _, pm_got, fc_got = independent_margins(design, model)
    assert pm_got == pytest.approx(pm, abs=1.0)
    assert fc_got == pytest.approx(fc, rel=0.02)


@pytest.mark.parametrize("motor", MOTORS)
@pytest.mark.parametrize("bandwidth_hz", [6.0, 8.0, 12.0])
def test_bandwidth_design(motor: str, bandwidth_hz: float) -> None:
    design = design_pi_bandwidth(MOTORS[motor], bandwidth_hz=bandwidth_hz, phase_margin_deg=60.0)
    assert design.target_bandwidth_hz == bandwidth_hz
    assert design.analysis()["phase_margin_deg"] == pytest.approx(60.0, abs=1e-6)
    z = np.exp(2j * np.pi * bandwidth_hz * TS)
    assert abs(design.closed_loop()(z)) == pytest.approx(1.0 / math.sqrt(2.0), rel=1e-6)
    lower = np.exp(2j * np.pi * np.linspace(0.01, 0.99 * bandwidth_hz, 200) * TS)
    assert np.all(np.abs(design.closed_loop()(lower)) > 1.0 / math.sqrt(2.0))


@pytest.mark.parametrize("bandwidth_hz", [1.0, 40.0])
def test_bandwidth_out_of_reach_is_refused(bandwidth_hz: float) -> None:
    with pytest.raises(InputError, match=r"cannot give a .* Hz closed-loop bandwidth.* Hz to"):
        design_pi_bandwidth(MOTORS["a"], bandwidth_hz=bandwidth_hz)


# -- runtime PI -----------------------------------------------------------------------------------
def test_is_a_controller() -> None:
    assert isinstance(PiController(0.2, 10.0, TS), Controller)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize(("pm", "fc", "extra"), REQUESTS[:4] + REQUESTS[-2:])
def test_runtime_equals_designed_transfer_function_when_unsaturated(
    mode: str, pm: float, fc: float, extra: int
) -> None:
    design = design_pi(MOTORS["a"], phase_margin_deg=pm, crossover_hz=fc, extra_delay_ticks=extra)
    pi = pi_for(design, anti_windup=mode)
    error = np.random.default_rng(7).normal(0.0, 0.3, 1000)
    error -= np.mean(error)
    expected = signal.lfilter(*design.controller_tf_coeffs(), error)
    assert np.max(np.abs(expected)) < 12.0  # the test stays linear
    got = np.array([pi.step(e, 0.0) for e in error])
    np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("motor", MOTORS)
def test_runtime_loop_equals_linear_closed_loop(motor: str) -> None:
    model = MOTORS[motor]
    design = design_pi(model, phase_margin_deg=60.0, crossover_hz=4.0)
    reference = np.r_[np.zeros(5), np.full(100, 3.0), np.full(100, -2.0)]
    speed, voltage = run_loop(pi_for(design), model, reference)
    assert np.max(np.abs(voltage)) < 12.0
    closed = design.closed_loop()
    num, den = closed.num_array[0, 0], closed.den_array[0, 0]
    num = np.r_[np.zeros(den.size - num.size), num]  # descending powers of z → powers of z⁻¹
    expected = signal.lfilter(num, den, reference)
    np.testing.assert_allclose(speed, expected, atol=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"voltage_limit_v": 12.5}, r"voltage limit .*\(0, 12\] V.*12\.5"),
        ({"voltage_limit_v": 0.0}, r"voltage limit"),
        ({"voltage_limit_v": math.inf}, r"voltage limit"),
        ({"anti_windup": "clamp"}, r"unknown anti-windup 'clamp'"),
        ({"tracking_gain": 0.5}, r"tracking_gain applies only to .*back-calculation"),
        ({"anti_windup": "back-calculation", "tracking_gain": 1.5}, r"\(0, 1\].*1\.5"),
        ({"kp": -0.1}, r"Kp must be .*>= 0.*-0\.1"),
        ({"ki": math.nan}, r"Ki must be"),
        ({"period_s": 0.0}, r"period must be .*> 0"),
    ],
)
def test_runtime_refuses_bad_settings(kwargs: dict[str, object], expected: str) -> None:
    args = {"kp": 0.2, "ki": 10.0, "period_s": TS} | kwargs
    with pytest.raises(InputError, match=expected):
        PiController(**args)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_input_gives_zero_volts_and_keeps_the_integral(bad: float) -> None:
    pi = PiController(0.2, 10.0, TS)
    pi.step(5.0, 0.0)
    held = pi.integral_v
    assert pi.step(bad, 0.0) == 0.0
    assert pi.step(5.0, bad) == 0.0
    assert pi.integral_v == held
    pi.reset()
    assert pi.integral_v == 0.0


class RecordingEstimator:
    """A stand-in estimator that records the calls and adds 1 rad/s to the measurement."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, float]] = []

    def reset(self) -> None:
        self.calls.append(("reset", 0.0))

    def correct(self, measured_rad_s: float) -> float:
        self.calls.append(("correct", measured_rad_s))
        return measured_rad_s + 1.0

    def predict(self, voltage_v: float) -> None:
        self.calls.append(("predict", voltage_v))


def test_estimator_is_corrected_first_and_predicts_with_the_command() -> None:
    est = RecordingEstimator()
    pi = PiController(1.0, 0.0, TS, voltage_limit_v=3.0, estimator=est)
    u = pi.step(10.0, 4.0)  # acts on 5 rad/s: u = 1·5 = 5 V, clamped to 3 V
    assert pi.estimate_rad_s == 5.0
    assert u == 3.0
    assert est.calls == [("reset", 0.0), ("correct", 4.0), ("predict", 3.0)]
    assert pi.step(10.0, math.nan) == 0.0  # no correction with a lost measurement
    assert est.calls[-1] == ("predict", 0.0)
    assert ("correct", math.nan) not in est.calls[3:]


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from(MODES),
    st.floats(min_value=0.1, max_value=12.0),
    st.floats(min_value=0.0, max_value=5.0),
    st.floats(min_value=0.0, max_value=200.0),
    st.lists(st.tuples(st.floats(), st.floats()), min_size=1, max_size=60),
)
def test_command_never_exceeds_the_limit(
    mode: str, limit: float, kp: float, ki: float, inputs: list[tuple[float, float]]
) -> None:
    pi = PiController(kp, ki, TS, voltage_limit_v=limit, anti_windup=mode)  # type: ignore[arg-type]
    for reference, measured in inputs:
        u = pi.step(reference, measured)
        assert math.isfinite(u)
        assert abs(u) <= limit


# -- windup and the recommended step ---------------------------------------------------------------
@pytest.mark.parametrize("motor", MOTORS)
def test_anti_windup_recovers_from_a_supply_drop(motor: str) -> None:
    """10 rad/s asked with only 4 V for 1 s (at most 8.1 rad/s), then the 12 V supply back."""
    model = MOTORS[motor]
    design = design_pi(model, phase_margin_deg=60.0, crossover_hz=4.0)
    reference = np.full(250, 10.0)
    limit = np.r_[np.full(100, 4.0), np.full(150, 12.0)]
    peaks, settling = {}, {}
    for mode in MODES:
        speed, voltage = run_loop(pi_for(design, anti_windup=mode), model, reference, limit)
        assert np.all(np.abs(voltage) <= limit)
        assert speed[99] == pytest.approx(4.0 * model.dc_gain(), rel=1e-3)
        after = step_info(np.arange(150) * TS, speed[100:], reference=10.0, initial=speed[99])
        peaks[mode], settling[mode] = after.peak_value, after.settling_time_s
    assert peaks["none"] > 20.0  # the wound-up integral drives it to full speed
    assert settling["none"] > 0.3
    for mode in ("conditional", "back-calculation"):
        assert peaks[mode] < 10.2
        assert settling[mode] < 0.2


@pytest.mark.parametrize("motor", MOTORS)
def test_anti_windup_recovers_from_an_unreachable_reference(motor: str) -> None:
    """30 rad/s for 2 s (12 V gives about 24 rad/s), then back to 10 rad/s."""
    model = MOTORS[motor]
    design = design_pi(model, phase_margin_deg=60.0, crossover_hz=4.0)
    reference = np.r_[np.full(200, 30.0), np.full(200, 10.0)]
    results = {}
    for mode in MODES:
        speed, voltage = run_loop(pi_for(design, anti_windup=mode), model, reference)
        assert np.max(np.abs(voltage)) <= 12.0
        results[mode] = step_info(
            np.arange(200) * TS, speed[200:], reference=10.0, initial=speed[199]
        )
    assert results["none"].settling_time_s > 0.6  # held at full speed while the integral unwinds
    for mode in ("conditional", "back-calculation"):
        assert results[mode].settling_time_s < 0.2
        assert results[mode].steady_state_error == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("motor", MOTORS)
def test_recommended_design_gives_a_good_10_rad_s_step(motor: str) -> None:
    model = MOTORS[motor]
    design = design_pi(model, **RECOMMENDED)
    speed, voltage = run_loop(pi_for(design), model, np.full(200, 10.0))
    info = step_info(np.arange(200) * TS, speed, reference=10.0)
    assert info.overshoot_percent <= 5.0
    assert info.steady_state_error == pytest.approx(0.0, abs=1e-9)
    assert info.settling_time_s is not None
    assert info.settling_time_s <= 0.08
    assert np.max(np.abs(voltage)) <= 12.0
