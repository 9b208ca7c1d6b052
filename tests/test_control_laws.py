"""One control law per controller: the runtime's per-tick laws on floats and on arrays.

The PI (:func:`cartctl.runtime.pi.pi_law`), state feedback
(:func:`cartctl.runtime.statefeedback.feedback_law`), the fixed-gain filter
(:func:`cartctl.runtime.kalman.filter_correct`, ``filter_predict``) and the ARX plant
(:func:`cartctl.plants.sim.arx_next`) are the code both ``cartctl run`` (one float per tick) and
``cartctl tune --robust`` (one array element per plant) step. Checked here: the anti-windup laws
against hand calculations, the array form against the float form element by element, and the
batch loop against the real loop bit for bit where saturation and anti-windup are active.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cartctl.data.modelfile import load_models
from cartctl.design.make import design_motor
from cartctl.design.request import DesignRequest
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant, arx_next
from cartctl.reference import reference_signal
from cartctl.runtime.base import Controller
from cartctl.runtime.loop import run_in_memory
from cartctl.runtime.pi import ANTI_WINDUP, PiController, pi_law
from cartctl.runtime.statefeedback import feedback_law
from cartctl.tune.batch import ArxBatch, simulate_batch

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
TS = 0.01


@pytest.mark.parametrize(
    ("mode", "error", "integral", "want_u", "want_integral"),
    [
        # Kp = 1, Ki·Ts = 0.5, Kt = 0.25, limit 10 V; unsaturated: u = e + I + 0.5 e
        ("conditional", 2.0, 1.0, 4.0, 2.0),
        # u = 8 + (4 + 4) = 16 > 10 pushing out: I may rise only to 10 − 8 = 2 < 4, so it holds 4
        ("conditional", 8.0, 4.0, 10.0, 4.0),
        # u = 7 + (0 + 3.5) = 10.5 > 10: I rises only to the edge 10 − 7 = 3
        ("conditional", 7.0, 0.0, 10.0, 3.0),
        # back-calculation: I = 8 + 0.25 (10 − 16) = 6.5
        ("back-calculation", 8.0, 4.0, 10.0, 6.5),
        ("none", 8.0, 4.0, 10.0, 8.0),
        # the error pulls back inside: integrates freely in every mode
        ("conditional", -2.0, 20.0, 10.0, 19.0),
    ],
)  # fmt: skip
def test_the_pi_law_by_hand(
    mode: str, error: float, integral: float, want_u: float, want_integral: float
) -> None:
    u, i = pi_law(error, integral, 1.0, 0.5, 0.25, ANTI_WINDUP.index(mode), 10.0)
    assert (u, i) == pytest.approx((want_u, want_integral), abs=1e-12)


@pytest.mark.parametrize("mode", ANTI_WINDUP)
def test_the_pi_law_on_arrays_is_the_float_law_per_element(mode: str) -> None:
    rng = np.random.default_rng(25)
    error = np.concatenate([rng.normal(0.0, 20.0, 200), [math.nan, math.inf, -math.inf, 1e308]])
    integral = rng.normal(0.0, 8.0, error.size)
    gains = (0.8, 0.4, 0.3, ANTI_WINDUP.index(mode), 12.0)
    with np.errstate(all="ignore"):  # as the batch loop steps it: a NaN row must not warn
        u, i = pi_law(error, integral, *gains)
    assert np.all(np.abs(u) <= 12.0) and np.any(np.abs(u) == 12.0)
    for k in range(error.size):
        uk, ik = pi_law(float(error[k]), float(integral[k]), *gains)
        assert (u[k], i[k]) == (uk, ik), k
    assert u[-4] == 0.0 and i[-4] == integral[-4]  # non-finite: 0 V, integral kept


def test_feedback_and_plant_laws_on_arrays_are_the_float_laws_per_element() -> None:
    rng = np.random.default_rng(5)
    r, y, xi = rng.normal(0.0, 15.0, (3, 100))
    state = list(rng.normal(0.0, 10.0, (3, 100)))
    terms = (0.9, -0.2, 1.1), 3.0, 2.5, TS
    raw, u, integral = feedback_law(r, y, state, xi, terms, 6.0)
    assert np.any(np.abs(raw) > 6.0)
    b, ar = (0.1, 0.05), (-1.2, 0.3)
    u_hist, y_hist = rng.normal(0.0, 5.0, (4, 100)), rng.normal(0.0, 9.0, (2, 100))
    y_next = arx_next(b, u_hist, 1, ar, y_hist)
    for k in range(100):
        one = feedback_law(r[k], y[k], [s[k] for s in state], xi[k], terms, 6.0)
        assert (raw[k], u[k], integral[k]) == one
        assert y_next[k] == arx_next(b, list(u_hist[:, k]), 1, ar, list(y_hist[:, k]))
    # by hand: 0.1·u[k−1] + 0.05·u[k−2] + 1.2·y[k] − 0.3·y[k−1]
    want = 0.1 * u_hist[1] + 0.05 * u_hist[2] + 1.2 * y_hist[0] - 0.3 * y_hist[1]
    np.testing.assert_allclose(y_next, want, rtol=1e-12, atol=1e-12)


def _plants() -> list[ArxModel]:
    base = load_models(GROUND).motor("a")
    gains = (1.0, 0.8, 1.25, 1.1)
    return [ArxModel(base.ar, tuple(g * b for b in base.b), nk, TS)
            for g, nk in zip(gains, (base.nk, base.nk, base.nk + 1, base.nk - 1), strict=True)]  # fmt: skip


@pytest.mark.parametrize(
    "make",
    [
        lambda: PiController(2.0, 60.0, TS, voltage_limit_v=6.0),
        lambda: PiController(2.0, 60.0, TS, voltage_limit_v=6.0, anti_windup="back-calculation"),
        lambda: design_motor(DesignRequest(method="poles", settling_time_s=0.04,
                                           overshoot_percent=2.0, voltage_limit_v=6.0),
                             load_models(GROUND).motor("a")).controller,
    ],
    ids=["pi-conditional", "pi-back-calculation", "poles"],
)  # fmt: skip
def test_the_batch_loop_is_the_real_loop_bit_for_bit_in_saturation(
    make: Callable[[], Controller],
) -> None:
    """A 20 rad/s square wave on a 6 V limit keeps the clamp and the anti-windup busy; the
    batch must give every plant's real-loop trace exactly, not merely within rounding."""
    plants = _plants()
    reference = reference_signal("square:20:0.6", 150, TS)
    batch = simulate_batch(make(), ArxBatch.from_models(plants), reference, voltage_limit_v=6.0)
    saturated = 0
    for i, plant in enumerate(plants):
        columns, state = run_in_memory(ArxPlant(plant, plant), {"a": make()},
                                       {"a": reference, "b": np.zeros(reference.size)},
                                       period_s=TS, voltage_limit_v=6.0)  # fmt: skip
        assert state.failure is None
        np.testing.assert_array_equal(batch.speed[i], columns["speed_a"])
        np.testing.assert_array_equal(batch.voltage[i], columns["voltage_a"])
        saturated += int(np.count_nonzero(np.abs(columns["voltage_a"]) == 6.0))
    assert saturated > 20
