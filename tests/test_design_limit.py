"""The time-optimal settling bound and its band: hand-computed cases and the delay-shift property."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from cartctl.data.modelfile import load_models
from cartctl.design.analysis import (
    StepAnalysis,
    in_settling_band,
    settling_band_rad_s,
    settling_bound,
)
from cartctl.errors import InputError
from cartctl.measures.stepinfo import step_info
from cartctl.model import ArxModel

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
QUANTUM = 2 * math.pi / 1792 / 0.01  # one encoder count per 10 ms tick, 0.3506 rad/s

# y[k+1] = 0.9 y[k] + 0.1 u[k]: DC gain 1 rad/s/V, nk = 1 (loop delay 0)
FIRST_ORDER = ArxModel((-0.9,), (0.1,), nk=1, period_s=0.01)


def _first_order_ticks(r: float, tol: float, u_max: float = 12.0, a: float = 0.9) -> int:
    """Full voltage from tick 0 gives y[N] = g U (1 − a^N) (g = 1), the fastest rise; holding r
    afterwards takes r / g = 10 V < U. So N is the first tick with U (1 − a^N) >= r − tol."""
    return math.ceil(math.log(1 - (r - tol) / u_max) / math.log(a))


def test_band_is_two_percent_or_one_encoder_count() -> None:
    assert settling_band_rad_s(10.0, 0.01) == pytest.approx(QUANTUM, rel=1e-12)
    assert abs(QUANTUM - 0.3506) < 1e-4
    assert settling_band_rad_s(-50.0, 0.01) == pytest.approx(1.0)  # 2 % of 50 > one count
    assert settling_band_rad_s(10.0, 0.01, quantum_rad_s=0.0) == pytest.approx(0.2)
    with pytest.raises(InputError, match="within its own settling band"):
        settling_band_rad_s(0.3, 0.01)


def test_first_order_bound_matches_the_hand_calculation() -> None:
    r = 10.0
    expected = _first_order_ticks(r, QUANTUM)
    plain = _first_order_ticks(r, 0.02 * r)
    assert (expected, plain) == (16, 17)  # the encoder-count band is the wider one here
    bound = settling_bound(FIRST_ORDER, r)
    assert bound.ticks == expected
    assert bound.settling_time_s == pytest.approx(expected * 0.01)
    assert bound.loop_delay_ticks == 0
    assert bound.band_rad_s == pytest.approx(QUANTUM)
    assert settling_bound(FIRST_ORDER, r, quantum_rad_s=0.0).ticks == plain
    # the sequence returned is admissible and settles at the bound, checked with scipy directly
    y = signal.lfilter([0.0, 0.1], [1.0, -0.9], bound.voltage_v)
    assert np.max(np.abs(bound.voltage_v)) <= 12.0 + 1e-9
    assert np.all(np.abs(y[expected : expected + 200] - r) <= QUANTUM + 1e-9)
    assert abs(y[expected - 1] - r) > QUANTUM


@pytest.mark.parametrize("extra", [1, 3])
def test_extra_delay_adds_exactly_its_ticks(extra: int) -> None:
    """A pure delay shifts the optimal sequence: the bound with d more ticks is the bound + d."""
    r = 10.0
    assert settling_bound(FIRST_ORDER, r, extra_delay_ticks=extra).ticks == 16 + extra
    models = load_models(GROUND)
    for motor in ("a", "b"):
        model = models.motor(motor)
        base = settling_bound(model, r)
        delayed = settling_bound(model, r, extra_delay_ticks=extra)
        assert delayed.ticks == base.ticks + extra
        assert delayed.settling_time_s == pytest.approx(base.settling_time_s + extra * 0.01)
        assert (base.loop_delay_ticks, delayed.loop_delay_ticks) == (1, 1 + extra)  # nk − 1 + d
        # the delayed plant's own simulation (scipy, numerator shifted by nk + d) of the sequence
        num = np.r_[np.zeros(model.nk + extra), model.b]
        y = signal.lfilter(num, np.r_[1.0, model.ar], delayed.voltage_v)
        np.testing.assert_allclose(delayed.speed_rad_s, y, atol=1e-9)
        assert np.all(y[: model.nk + extra] == 0.0)
        assert np.all(np.abs(y[delayed.ticks : delayed.ticks + 200] - r) <= QUANTUM + 1e-9)


def test_negative_extra_delay_is_refused() -> None:
    with pytest.raises(InputError, match="extra delay"):
        settling_bound(FIRST_ORDER, 10.0, extra_delay_ticks=-1)


def test_a_step_is_measured_in_the_same_band() -> None:
    """y[k] = r (1 − 0.5^k): |y − r| = 10 · 0.5^k falls below 0.3506 between ticks 4 and 5."""
    r, n = 10.0, 200
    k = np.arange(n)
    speed = r * (1 - 0.5**k)
    step = StepAnalysis(k * 0.01, np.full(n, r), speed, speed, np.zeros(n),
                        step_info(k * 0.01, speed, reference=r))  # fmt: skip
    banded = in_settling_band(step, 0.01)
    z4, z5, edge = 1 - 0.5**4, 1 - 0.5**5, 1 - QUANTUM / r
    by_hand = (4 + (edge - z4) / (z5 - z4)) * 0.01
    assert banded.info.settling_time_s == pytest.approx(by_hand, rel=1e-9)
    assert step.info.settling_time_s > 0.05  # the plain 2 % band is entered only after tick 5
    assert banded.info.overshoot_percent == step.info.overshoot_percent
