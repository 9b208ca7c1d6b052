"""Empirical transfer function (cartctl.identification.etfe)."""

from __future__ import annotations

import numpy as np
import pytest

from cartctl.errors import InputError
from cartctl.identification.etfe import Etfe, etfe, model_response
from cartctl.model import ArxModel
from cartctl.signals import multisine, prbs, square

TS = 0.01
GROUND_A = ArxModel((-0.9356, 0.2173), (0.6466, -0.07751), nk=2, period_s=TS)
SLOW = ArxModel((-1.6, 0.68), (0.3, 0.1, -0.05), nk=1, period_s=TS)  # complex poles, |p| ≈ 0.82


def response_from_theta(model: ArxModel, freq_hz: np.ndarray) -> np.ndarray:
    """H = q^-nk B(q^-1) / A(q^-1) at q = e^{jωTs}, written from θ (independent of num/den)."""
    w = np.exp(-2j * np.pi * freq_hz * model.period_s)  # q^-1
    b = sum(c * w ** (model.nk + i) for i, c in enumerate(model.b))
    a = 1.0 + sum(c * w ** (i + 1) for i, c in enumerate(model.ar))
    return b / a


@pytest.mark.parametrize("model", [GROUND_A, SLOW])
def test_model_response_matches_theta_form(model: ArxModel) -> None:
    f = np.linspace(0.0, 50.0, 37)
    np.testing.assert_allclose(model_response(model, f), response_from_theta(model, f), atol=1e-12)
    assert model_response(model, [0.0])[0] == pytest.approx(model.dc_gain())


@pytest.mark.parametrize(
    ("model", "u", "period"),
    [
        (GROUND_A, square(10.0, cycles=5), 300),
        (SLOW, square(10.0, cycles=5), 300),
        (GROUND_A, multisine(5.0, duration_s=2.56 * 4), 256),
        (SLOW, prbs(5.0, duration_s=3 * 12.75), 1275),
    ],
)
def test_periodic_etfe_is_exact_on_noise_free_data(
    model: ArxModel, u: np.ndarray, period: int
) -> None:
    e = etfe(model.simulate(u), u, TS, period_ticks=period)
    assert e.periodic
    assert e.n_segments == u.size // period - 1
    expected = response_from_theta(model, e.freq_hz)
    np.testing.assert_allclose(e.response, expected, rtol=1e-8, atol=0)
    assert e.response_std is not None
    assert np.all(e.response_std < 1e-8 * np.abs(expected))


def test_periodic_etfe_keeps_excited_harmonics_only() -> None:
    u = square(10.0, cycles=4)
    e = etfe(GROUND_A.simulate(u), u, TS, period_ticks=300)
    harmonic = np.rint(e.freq_hz * 3.0).astype(int)  # multiples of 1/3 Hz
    np.testing.assert_allclose(e.freq_hz, harmonic / 3.0, atol=1e-12)
    assert 0 not in harmonic  # no DC: the square wave has no mean
    assert not np.any(harmonic % 3 == 0)  # the square wave does not excite 3k/3 Hz
    assert len(e.freq_hz) == 100
    assert e.freq_hz.max() <= 0.5 / TS


def test_periodic_etfe_keeps_dc_when_excited() -> None:
    u = square(10.0, cycles=4) + 2.0
    e = etfe(GROUND_A.simulate(u), u, TS, period_ticks=300)
    assert e.freq_hz[0] == 0.0
    assert e.response[0] == pytest.approx(GROUND_A.dc_gain(), rel=1e-9)


def test_periodic_etfe_with_one_period_after_the_transient() -> None:
    u = square(10.0, cycles=2)
    e = etfe(GROUND_A.simulate(u), u, TS, period_ticks=300)
    assert e.n_segments == 1
    assert e.response_std is None
    np.testing.assert_allclose(e.response, response_from_theta(GROUND_A, e.freq_hz), rtol=1e-8)


def test_periodic_etfe_std_tracks_noise() -> None:
    rng = np.random.default_rng(7)
    u = square(10.0, cycles=21)
    y = GROUND_A.simulate(u) + 0.5 * rng.standard_normal(u.size)
    e = etfe(y, u, TS, period_ticks=300)
    assert e.response_std is not None
    z = (e.response - response_from_theta(GROUND_A, e.freq_hz)) / e.response_std
    # Complex errors over their estimated std: E|z|² ≈ 1 when the std is right.
    assert np.mean(np.abs(z) ** 2) == pytest.approx(1.0, abs=0.35)


def test_segment_average_approximates_non_periodic_data() -> None:
    u = prbs(5.0, duration_s=60.0, bit_s=0.02)
    y = GROUND_A.simulate(u)
    e = etfe(y, u, TS, segments=8)
    assert not e.periodic
    assert e.n_segments == 8
    assert e.response_std is None
    error = np.abs(e.response - response_from_theta(GROUND_A, e.freq_hz))
    assert np.median(error / np.abs(e.response)) < 0.01


def test_whole_record_etfe() -> None:
    u = prbs(5.0, duration_s=10.0)
    e = etfe(GROUND_A.simulate(u), u, TS)
    assert not e.periodic
    assert e.n_segments == 1
    assert np.all(np.isfinite(e.response))
    assert np.all(np.diff(e.freq_hz) > 0)


def test_etfe_to_dict_and_views() -> None:
    u = square(10.0, cycles=3)
    e = etfe(GROUND_A.simulate(u), u, TS, period_ticks=300)
    d = e.to_dict()
    assert set(d) == {"freq_hz", "re", "im", "periodic", "n_segments", "period_s", "response_std"}
    assert len(d["re"]) == len(e.freq_hz)
    np.testing.assert_allclose(e.magnitude_db(), 20 * np.log10(np.abs(e.response)))
    assert np.all(np.abs(e.phase_deg()) <= 180.0)
    with pytest.raises(ValueError, match="read-only"):
        e.response[0] = 0.0
    assert isinstance(e, Etfe)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"period_ticks": 300}, "does not repeat"),
        ({"period_ticks": 2000}, "whole cycle"),
        ({"segments": 0}, "segments"),
        ({"segments": 400}, "fewer segments"),
        ({"min_input_fraction": 1.5}, "min_input_fraction"),
    ],
)
def test_etfe_errors(kwargs: dict, message: str) -> None:
    u = prbs(5.0)
    with pytest.raises(InputError, match=message):
        etfe(GROUND_A.simulate(u), u, TS, **kwargs)


def test_etfe_rejects_zero_input_and_bad_period() -> None:
    with pytest.raises(InputError, match="zero throughout"):
        etfe(np.zeros(100), np.zeros(100), TS)
    with pytest.raises(InputError, match="period_s"):
        etfe(np.zeros(100), np.ones(100), 0.0)
