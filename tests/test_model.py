"""Model maths: poles, zeros, frequencies, DC gain, simulation, conversions."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import signal

from cartctl.errors import InputError
from cartctl.model import ArxModel, classify_root, format_poly

# Equation 12 of the report (cart on the ground) and equation 8 (in the air), θ = [c, d, a, b].
GROUND_A = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751])
GROUND_B = ArxModel.from_theta([-0.9082, 0.1968, 0.6886, -0.1068])
AIR_A = ArxModel.from_theta([-0.5393, 0.0373, 1.0812, -0.0323])


def _freqs(model: ArxModel, kind: str = "pole") -> list[float]:
    roots = model.poles() if kind == "pole" else model.zeros()
    return sorted(r.freq_hz for r in roots if r.freq_hz is not None)


def test_report_structure_num_den() -> None:
    np.testing.assert_array_equal(GROUND_A.den(), [1.0, -0.9356, 0.2173, 0.0])
    np.testing.assert_array_equal(GROUND_A.num(), [0.6466, -0.07751])
    np.testing.assert_array_equal(GROUND_A.theta, [-0.9356, 0.2173, 0.6466, -0.07751])


@pytest.mark.parametrize(
    ("model", "pole_hz", "zero_hz", "dc_gain"),
    [
        (GROUND_A, [10.84, 13.45], [33.76], 2.020),  # report: 10.84 Hz, 13.45 Hz, zero 33.76 Hz
        (GROUND_B, [9.48, 16.38], [29.66], 2.016),
        (AIR_A, [12.43, 39.90], [55.86], 2.106),  # report §3.1: 12.4344, 39.9032, 55.8634 Hz
    ],
)
def test_report_frequencies(
    model: ArxModel, pole_hz: list[float], zero_hz: list[float], dc_gain: float
) -> None:
    np.testing.assert_allclose(_freqs(model), pole_hz, rtol=3e-3)
    np.testing.assert_allclose(_freqs(model, "zero"), zero_hz, rtol=3e-3)
    assert model.dc_gain() == pytest.approx(dc_gain, rel=1e-3)
    assert model.is_stable()


def test_delay_pole_has_no_frequency() -> None:
    delay = [r for r in GROUND_A.poles() if r.kind == "delay"]
    assert len(delay) == 1
    assert delay[0].value == 0
    assert delay[0].freq_hz is None
    assert delay[0].damping is None
    assert delay[0].to_dict() == {
        "re": 0.0,
        "im": 0.0,
        "kind": "delay",
        "freq_hz": None,
        "damping": None,
    }


@pytest.mark.parametrize(
    ("z", "freq_hz", "damping"),
    [
        (math.exp(-0.5), 0.5 / (2 * math.pi * 0.01), 1.0),  # real positive: s = ln z / Ts
        # negative real: s = (ln|z| + jπ) / Ts, at or above the Nyquist 50 Hz (as control.damp)
        (
            -0.5,
            math.hypot(math.log(0.5), math.pi) / (2 * math.pi * 0.01),
            -math.log(0.5) / math.hypot(math.log(0.5), math.pi),
        ),
        (-1.0, 50.0, 0.0),
        (1.2, math.log(1.2) / (2 * math.pi * 0.01), -1.0),  # unstable real pole
    ],
)
def test_classify_root(z: complex, freq_hz: float, damping: float) -> None:
    root = classify_root(z, "pole", 0.01)
    assert root.kind == "pole"
    assert root.freq_hz == pytest.approx(freq_hz)
    assert root.damping == pytest.approx(damping)


def test_complex_pair_matches_continuous_system() -> None:
    # A continuous pole pair ω_n = 30 rad/s, ζ = 0.3 mapped to z = exp(s Ts).
    wn, zeta, ts = 30.0, 0.3, 0.01
    s = complex(-zeta * wn, wn * math.sqrt(1 - zeta**2))
    root = classify_root(np.exp(s * ts), "pole", ts)
    assert root.freq_hz == pytest.approx(wn / (2 * math.pi))
    assert root.damping == pytest.approx(zeta)


def test_negative_real_zero_oscillates_at_nyquist() -> None:
    # Equation 10 (motor A, filtered) has numerator 1.266 z + 1.029: a zero at −0.8128.
    model = ArxModel.from_theta([-1.044, 0.1567, 1.266, 1.029])
    (zero,) = model.zeros()
    assert zero.value.real == pytest.approx(-1.029 / 1.266)
    # s = (ln 0.8128 + jπ) / Ts: Im(s) is the Nyquist frequency, |s| a little above it
    s = complex(math.log(1.029 / 1.266), math.pi) / 0.01
    assert s.imag / (2 * math.pi) == pytest.approx(50.0)
    assert zero.freq_hz == pytest.approx(abs(s) / (2 * math.pi))


@pytest.mark.parametrize("nk", [1, 2, 3, 4])
def test_simulate_matches_lfilter_and_difference_equation(nk: int) -> None:
    rng = np.random.default_rng(4)
    model = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751], nk=nk)
    u = rng.normal(0.0, 5.0, 400)
    y = model.simulate(u)
    # scipy.signal.lfilter on the transfer function in descending powers of z
    num_z = np.concatenate([np.zeros(len(model.den()) - len(model.num())), model.num()])
    np.testing.assert_allclose(y, signal.lfilter(num_z, model.den(), u), atol=1e-12)
    # the report's difference equation, written out
    c, d, a, b = model.theta
    ref = np.zeros_like(u)
    for k in range(u.size):

        def uu(i: int) -> float:
            return u[i] if i >= 0 else 0.0

        ref[k] = -c * (ref[k - 1] if k >= 1 else 0) - d * (ref[k - 2] if k >= 2 else 0)
        ref[k] += a * uu(k - nk) + b * uu(k - nk - 1)
    np.testing.assert_allclose(y, ref, atol=1e-12)


def test_to_tf_agrees_with_python_control() -> None:
    sys = GROUND_A.to_tf()
    assert sys.dt == 0.01
    assert control.dcgain(sys) == pytest.approx(GROUND_A.dc_gain())
    np.testing.assert_allclose(
        np.sort_complex(sys.poles()),
        np.sort_complex([r.value for r in GROUND_A.poles()]),
        atol=1e-12,
    )
    t = np.arange(200) * 0.01
    u = np.sin(3 * t) * 8
    resp = control.forced_response(sys, T=t, U=u)
    np.testing.assert_allclose(resp.outputs, GROUND_A.simulate(u), atol=1e-10)


def test_step_response_reaches_dc_gain() -> None:
    t, y = GROUND_B.step_response(10.0, duration_s=2.0)
    assert t[1] - t[0] == pytest.approx(0.01)
    assert y[0] == 0.0 and y[1] == 0.0  # two samples of delay
    assert y[-1] == pytest.approx(10.0 * GROUND_B.dc_gain(), rel=1e-6)


@pytest.mark.parametrize(
    ("na", "nb", "nk"), [(1, 1, 1), (2, 2, 2), (3, 2, 1), (2, 3, 4), (0, 2, 1)]
)
def test_from_tf_round_trip(na: int, nb: int, nk: int) -> None:
    rng = np.random.default_rng(na * 100 + nb * 10 + nk)
    model = ArxModel.from_theta(rng.uniform(-0.3, 0.3, na + nb), na=na, nb=nb, nk=nk)
    again = ArxModel.from_tf(model.num(), model.den(), period_s=model.period_s)
    assert again.nk == nk
    np.testing.assert_allclose(again.theta, model.theta)


def test_integrator_dc_gain_is_infinite() -> None:
    model = ArxModel.from_theta([-1.0, 0.5], na=1, nb=1, nk=1)
    assert model.dc_gain() == math.inf
    assert not model.is_stable()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"theta": [1, 2, 3]}, "theta has 3 values"),
        ({"theta": [0.1, 0.2, float("nan"), 1.0]}, "finite"),
        ({"theta": [0.1, 0.2, 0.3, 1.0], "nk": -1}, "nk"),
        ({"theta": [0.1, 0.2, 0.3, 1.0], "period_s": 0.0}, "sample period"),
    ],
)
def test_bad_models_are_refused(kwargs: dict, message: str) -> None:
    theta = kwargs.pop("theta")
    with pytest.raises(InputError, match=message):
        ArxModel.from_theta(theta, **kwargs)


def test_format_poly() -> None:
    assert format_poly([1.0, -0.9356, 0.2173, 0.0]) == "z³ − 0.9356 z² + 0.2173 z"
    assert format_poly([0.6466, -0.07751]) == "0.6466 z − 0.07751"
    assert format_poly([-2.0]) == "−2"


@settings(max_examples=60, deadline=None)
@given(st.floats(-2.0, 2.0), st.floats(-1.5, 1.5))
def test_stable_iff_poles_inside_unit_circle(c: float, d: float) -> None:
    model = ArxModel.from_theta([c, d, 1.0, 0.2])
    radii = np.abs(np.roots([1.0, c, d]))
    assume(abs(max(radii) - 1.0) > 1e-9)  # on the circle itself, rounding decides
    assert model.is_stable() == bool(np.all(radii < 1.0))
    # a stable model's step response settles at its DC gain
    if model.is_stable() and max(radii) < 0.9:
        _, y = model.step_response(1.0, duration_s=3.0)
        assert y[-1] == pytest.approx(model.dc_gain(), rel=1e-6, abs=1e-9)


@pytest.mark.parametrize(("na", "nb", "nk"), [(2, 2, 2), (3, 1, 1), (1, 3, 4)])
def test_response_at_matches_freqz_of_the_difference_equation(na: int, nb: int, nk: int) -> None:
    # scipy's freqz evaluates B(q⁻¹)/A(q⁻¹) from the lfilter form, not from num()/den()
    theta = np.r_[np.linspace(-0.5, 0.2, na), np.linspace(1.0, 0.3, nb)]
    model = ArxModel.from_theta(theta, na=na, nb=nb, nk=nk)
    w = np.linspace(0.01, np.pi, 50)
    _, expected = signal.freqz(np.r_[np.zeros(nk), theta[na:]], np.r_[1.0, theta[:na]], worN=w)
    np.testing.assert_allclose(model.response_at(np.exp(1j * w)), expected, rtol=1e-10)
