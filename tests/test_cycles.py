"""Cycle detection and averaging (cartctl.identification.etfe)."""

from __future__ import annotations

import numpy as np
import pytest

from cartctl.choices import is_whole
from cartctl.errors import InputError
from cartctl.identification.etfe import (
    as_pair,
    average_cycles,
    find_period,
    periodic_regression_pad,
    split_cycles,
)
from cartctl.model import ArxModel
from cartctl.signals import multisine, prbs, square


@pytest.mark.parametrize(
    ("u", "expected"),
    [
        (square(10.0, cycles=5), 300),  # the report's square wave, 1 s holds at 10 ms
        (square(10.0, hold_s=0.5, cycles=3), 150),
        (square(10.0, cycles=2), 300),  # exactly two periods
        (square(10.0, cycles=3)[:-50], 300),  # a trailing partial period is fine
        (multisine(5.0, duration_s=7.68), 256),  # three 2.56 s cycles
        (prbs(5.0, duration_s=30.0), 1275),  # 255 bits of 5 ticks repeat
        (np.tile([0.0, 1.0, -1.0], 20), 12),  # fundamental 3 < min_ticks: smallest multiple
    ],
)
def test_find_period_periodic(u: np.ndarray, expected: int) -> None:
    assert find_period(u) == expected


def test_find_period_tolerates_rounding_noise() -> None:
    u = square(10.0, cycles=4) + 1e-12 * np.random.default_rng(0).standard_normal(1200)
    assert find_period(u) == 300


@pytest.mark.parametrize(
    "u",
    [
        prbs(5.0),  # 15 s of a 12.75 s sequence: fewer than two periods
        square(10.0, cycles=3)[:599],  # just short of two periods
        np.random.default_rng(1).standard_normal(2000),
        np.zeros(1000),  # constant: no excitation
        np.full(1000, 3.0),
        np.where(np.arange(1200) == 750, 3.0, square(10.0, cycles=4)),  # one sample off
        np.arange(15.0),  # shorter than two minimum periods
    ],
)
def test_find_period_none(u: np.ndarray) -> None:
    assert find_period(u) is None


def test_find_period_min_ticks() -> None:
    u = np.tile(np.r_[np.ones(20), -np.ones(20)], 4)
    assert find_period(u) == 40
    assert find_period(u, min_ticks=50) == 80
    assert find_period(u, min_ticks=90) is None


@pytest.mark.parametrize("bad", [0, -3, 2.5, True])
def test_find_period_rejects_min_ticks(bad: object) -> None:
    with pytest.raises(InputError, match="min_ticks"):
        find_period(square(1.0), min_ticks=bad)  # type: ignore[arg-type]


def test_find_period_rejects_bad_input() -> None:
    with pytest.raises(InputError, match="1-D"):
        find_period(np.ones((10, 10)))
    with pytest.raises(InputError, match="NaN"):
        find_period(np.r_[square(1.0), np.nan])


def test_average_cycles_exact_on_steady_state() -> None:
    model = ArxModel((-0.9356, 0.2173), (0.6466, -0.07751))
    u = square(10.0, cycles=5)
    y = model.simulate(u)
    y_avg, u_avg, n = average_cycles(y, u, 300)
    assert n == 4
    np.testing.assert_array_equal(u_avg, u[:300])
    np.testing.assert_allclose(y_avg, y[-300:], rtol=0, atol=1e-12)
    _, _, n_all = average_cycles(y, u, 300, skip_first=False)
    assert n_all == 5


def test_averaging_divides_noise_variance_by_cycles() -> None:
    rng = np.random.default_rng(42)
    period, sigma = 300, 0.5
    u = square(10.0, cycles=41)  # 40 cycles after the first
    clean = np.tile(np.sin(np.linspace(0.0, 2.0 * np.pi, period, endpoint=False)), 41)
    trials = np.array(
        [
            average_cycles(clean + sigma * rng.standard_normal(clean.size), u, period)[0]
            for _ in range(50)
        ]
    )
    n = 40
    variance = np.var(trials - clean[:period], axis=(0, 1))
    # 15 000 samples of the averaged noise: the variance estimate is within a few percent.
    assert variance == pytest.approx(sigma**2 / n, rel=0.05)


def test_average_cycles_drops_partial_cycle() -> None:
    u = square(1.0, hold_s=0.1, cycles=4)
    y = np.arange(u.size, dtype=float)
    y_avg, _, n = average_cycles(y[:-5], u[:-5], 30)
    assert n == 2  # cycles 2 and 3; the cut 4th is dropped
    np.testing.assert_allclose(y_avg, np.arange(30) + 45.0)


@pytest.mark.parametrize(
    ("cycles", "skip_first", "message"),
    [(2, True, "after dropping the first"), (1, False, "at least 2")],
)
def test_average_cycles_too_few(cycles: int, skip_first: bool, message: str) -> None:
    u = square(10.0, cycles=cycles)
    with pytest.raises(InputError, match=message):
        average_cycles(np.zeros_like(u), u, 300, skip_first=skip_first)


def test_average_cycles_rejects_non_periodic_input() -> None:
    u = square(10.0, cycles=4)
    u[700] = 1.0
    with pytest.raises(InputError, match="does not repeat every 300"):
        average_cycles(np.zeros_like(u), u, 300)


@pytest.mark.parametrize("period", [0, -1, 1.5])
def test_average_cycles_rejects_period(period: object) -> None:
    u = square(10.0, cycles=4)
    with pytest.raises(InputError, match="period_ticks"):
        average_cycles(u, u, period)  # type: ignore[arg-type]


def test_average_cycles_rejects_unequal_lengths() -> None:
    with pytest.raises(InputError, match="equally long"):
        average_cycles(np.zeros(900), np.zeros(901), 300)


def test_split_cycles_allows_one_cycle() -> None:
    u = square(10.0, cycles=2)
    y_cycles, u_cycles = split_cycles(u, u, 300, min_cycles=1)
    assert y_cycles.shape == u_cycles.shape == (1, 300)


def test_periodic_regression_pad_gives_exact_regression() -> None:
    """A least-squares fit over one padded steady-state cycle recovers the model exactly."""
    model = ArxModel((-0.9356, 0.2173), (0.6466, -0.07751), nk=2)
    u = square(10.0, cycles=4)
    y_avg, u_avg, _ = average_cycles(model.simulate(u), u, 300)
    lags = 3
    y_ext, u_ext = periodic_regression_pad(y_avg, u_avg, lags)
    assert y_ext.shape == u_ext.shape == (303,)
    np.testing.assert_array_equal(y_ext[:3], y_avg[-3:])
    np.testing.assert_array_equal(u_ext[3:], u_avg)
    k = np.arange(lags, lags + 300)
    phi = np.column_stack([-y_ext[k - 1], -y_ext[k - 2], u_ext[k - 2], u_ext[k - 3]])
    theta, *_ = np.linalg.lstsq(phi, y_ext[k], rcond=None)
    np.testing.assert_allclose(theta, model.theta, rtol=0, atol=1e-9)


def test_periodic_regression_pad_zero_lags_and_errors() -> None:
    y, u = np.arange(5.0), np.ones(5)
    y_ext, u_ext = periodic_regression_pad(y, u, 0)
    np.testing.assert_array_equal(y_ext, y)
    np.testing.assert_array_equal(u_ext, u)
    with pytest.raises(InputError, match="lags"):
        periodic_regression_pad(y, u, 6)
    with pytest.raises(InputError, match="equally long"):
        periodic_regression_pad(y, u[:4], 1)


@pytest.mark.parametrize(("value", "whole"), [(3, True), (np.int64(3), True), (0, True),
    (True, False), (np.bool_(True), False), (3.0, False), ("3", False), (None, False)])  # fmt: skip
def test_is_whole(value: object, whole: bool) -> None:
    assert is_whole(value) is whole


def test_as_pair_names_what_it_refuses() -> None:
    y, u = as_pair([1, 2, 3], (0.0, 1.0, 0.5))
    assert y.dtype == u.dtype == np.float64
    np.testing.assert_array_equal(y, [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match=r"^output and input must be equally long, got 3 and 2"):
        as_pair([1, 2, 3], [0, 1])
    with pytest.raises(InputError, match=r"^averaged input u_avg holds NaN"):
        as_pair([1.0], [np.nan], names=("averaged output y_avg", "averaged input u_avg"))
    with pytest.raises(InputError, match=r"^input sequence u must be 1-D"):
        as_pair([1.0], [[1.0]])


def test_period_and_lags_refuse_booleans() -> None:
    u = square(10.0, cycles=4)
    with pytest.raises(InputError, match="period_ticks"):
        split_cycles(u, u, True)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="lags"):
        periodic_regression_pad(np.zeros(5), np.zeros(5), True)  # type: ignore[arg-type]
