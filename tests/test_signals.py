"""Excitation signals: shapes, amplitudes, durations, spectra, and refused requests."""

from __future__ import annotations

import re

import numpy as np
import pytest

from cartctl.errors import InputError
from cartctl.signals import SIGNALS, chirp, make_signal, multisine, prbs, ramp, square, step


def test_square_is_the_reports_cycle() -> None:
    u = square(10.0, hold_s=1.0, cycles=2)
    assert u.size == 600
    np.testing.assert_array_equal(u[:100], 10.0)
    np.testing.assert_array_equal(u[100:200], 0.0)
    np.testing.assert_array_equal(u[200:300], -10.0)
    np.testing.assert_array_equal(u[300:], u[:300])
    assert u.mean() == 0.0  # no DC component over whole cycles


def test_step() -> None:
    u = step(7.0, duration_s=2.0, delay_s=0.5)
    assert u.size == 200
    assert (u[:50] == 0).all() and (u[50:] == 7.0).all()


def test_prbs_is_binary_balanced_and_reproducible() -> None:
    u = prbs(5.0, duration_s=25.5, bit_s=0.1, order=8)
    assert set(np.unique(u)) == {-5.0, 5.0}
    assert u.size == 2550
    # A maximum-length sequence has one more +1 than −1 per period of 255 bits.
    assert abs(u[: 255 * 10].sum()) == pytest.approx(5.0 * 10)
    np.testing.assert_array_equal(u, prbs(5.0, duration_s=25.5, bit_s=0.1, order=8))
    runs = np.diff(np.flatnonzero(np.diff(u)))
    assert runs.min() >= 10  # never shorter than one bit


def test_multisine_has_low_crest_factor_and_its_band() -> None:
    u = multisine(10.0, duration_s=2.56 * 4, cycle_s=2.56, f_min_hz=0.5, f_max_hz=20.0)
    assert np.max(np.abs(u)) == pytest.approx(10.0)
    crest = np.max(np.abs(u)) / np.sqrt(np.mean(u**2))
    assert crest < 2.0  # zero-phase multisine of these 50 lines would be ~10
    spectrum = np.abs(np.fft.rfft(u[:256]))
    freqs = np.fft.rfftfreq(256, 0.01)
    excited = freqs[spectrum > 0.1 * spectrum.max()]
    assert excited.min() >= 0.5 - 1e-9 and excited.max() <= 20.0 + 1e-9
    np.testing.assert_allclose(u[256:512], u[:256], atol=1e-12)  # periodic


def test_chirp_sweeps_its_band() -> None:
    u = chirp(6.0, duration_s=20.0, f_start_hz=0.2, f_end_hz=10.0)
    assert u.size == 2000
    assert np.max(np.abs(u)) <= 6.0 + 1e-12
    assert u[0] == pytest.approx(6.0)  # cosine sweep starts at the peak
    early = np.count_nonzero(np.diff(np.sign(u[:200])))
    late = np.count_nonzero(np.diff(np.sign(u[-200:])))
    assert late > 5 * early  # the frequency rises


def test_ramp_with_limit() -> None:
    r = ramp(4.0, duration_s=5.0, limit=10.0)
    assert r[100] == pytest.approx(4.0)
    assert r.max() == 10.0


@pytest.mark.parametrize("name", SIGNALS)
def test_make_signal_every_name(name: str) -> None:
    u = make_signal(name, 8.0)
    assert u.ndim == 1 and u.size > 100
    assert np.max(np.abs(u)) == pytest.approx(8.0)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: square(-1.0), "amplitude"),
        (lambda: square(float("nan")), "amplitude"),
        (lambda: square(5.0, cycles=0), "cycles"),
        (lambda: square(5.0, hold_s=0.001), "shorter than one sample"),
        (lambda: step(5.0, duration_s=1.0, delay_s=2.0), "delay"),
        (lambda: multisine(5.0, f_max_hz=60.0), "band"),
        (lambda: chirp(5.0, f_end_hz=80.0), "chirp frequencies"),
        (lambda: make_signal("sawtooth", 5.0), "unknown signal 'sawtooth'"),
        (lambda: make_signal("chirp", 5.0, cycles=2), "--cycles does not apply to the chirp"),
        (lambda: make_signal("multisine", 5.0, cycles=2, duration_s=3.0), "give one"),
    ],
)
def test_bad_requests_are_refused(call, message: str) -> None:
    with pytest.raises(InputError, match=message):
        call()


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda: make_signal("square", 5.0, cycles=True),
            "--cycles must be a whole number, got True",
        ),
        (lambda: make_signal("multisine", 5.0, cycles=np.bool_(True)), "--cycles must be a whole"),
        (lambda: square(5.0, cycles=True), "cycles must be a whole number >= 1, got True"),
        (lambda: square(5.0, cycles=2.5), "cycles must be a whole number >= 1, got 2.5"),
        (lambda: prbs(5.0, order=8.0), "PRBS order must be a whole number in 2..32, got 8.0"),
        (lambda: prbs(5.0, seed=True), "PRBS seed must be a whole number, got True"),
    ],
)
def test_a_count_that_is_not_whole_is_refused(call, message: str) -> None:
    # cycles=True ran as 1 cycle (the project's rule, choices.is_whole, refuses bools); 2.5 and
    # 8.0 raised numpy's or range's TypeError
    with pytest.raises(InputError, match=re.escape(message)):
        call()


def test_numpy_whole_numbers_are_counts() -> None:
    np.testing.assert_array_equal(make_signal("square", 5.0, cycles=np.int64(2)),
                                  square(5.0, cycles=2))  # fmt: skip
    np.testing.assert_array_equal(prbs(5.0, order=np.int32(8), seed=np.int64(1)), prbs(5.0))


def test_a_step_no_longer_than_its_wait_names_duration(capsys, tmp_path, monkeypatch) -> None:
    """excite's step holds 0 V for 0.5 s: --duration 0.5 was refused as 'step delay must be in
    [0, duration), got 0.5 s', naming no option the user has."""
    from cartctl.cli import main

    monkeypatch.chdir(tmp_path)
    code = main(
        ["excite", "--signal", "step", "--amplitude", "3", "--duration", "0.5", "--out", "x"]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "--duration 0.5 s" in err[0] and "0.51 s" in err[0] and "delay" not in err[0], err[0]
    assert not list(tmp_path.iterdir())
    assert make_signal("step", 3.0, duration_s=0.51)[-1] == 3.0  # the shortest: one tick of step
