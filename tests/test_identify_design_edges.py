"""Edges of identification and design through the Python API: the order of errors for a request
with two faults, refusals of odd motor names, a controller's frequency response at points of any
shape, validate's NaN fit on a non-finite Trace, and fit_oe's refusal of too few samples."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from cartctl.data.trace import Trace
from cartctl.design.controller_ss import controller_state_space
from cartctl.errors import InputError
from cartctl.identification.pipeline import IdentifyRequest, identify


def _trace(n: int, seed: int = 0) -> Trace:
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-6.0, 6.0], size=n // 5 + 1), 5)[:n]
    y = signal.lfilter([0.0, 0.0, 0.6466, -0.07751], [1.0, -0.9356, 0.2173], u)
    y = y + rng.normal(0.0, 0.1, n)
    z = np.zeros(n)
    return Trace(np.arange(n) * 0.01, u, z, y, z, source=f"t{seed}.csv")


def test_too_short_validation_is_refused_before_the_order_table() -> None:
    # two faults: validation data too short for the residual tests and an order grid with a
    # combination check_orders refuses; the residual tests come first
    # (which also spared a long grid's fits before that refusal)
    request = IdentifyRequest(motors=("a",), orders={"na": (1,), "nb": (0,), "nk": (1,)})
    with pytest.raises(InputError, match="too few residual samples"):
        identify([_trace(2000)], request, validation=[_trace(15, seed=1)])


def test_order_table_still_computed_after_the_diagnostics() -> None:
    request = IdentifyRequest(motors=("a",), orders={"na": (1, 2), "nb": (1, 2), "nk": (2,)})
    result = identify([_trace(2000)], request)
    orders = result.motors["a"].diagnostics.orders
    assert orders is not None and len(orders.rows) == 4


@pytest.mark.parametrize("motors", [(["a"],), ({"a"},), ("a", ["b"])])
def test_unhashable_motor_names_are_an_input_error(motors: tuple) -> None:
    with pytest.raises(InputError, match="motors must be 'a' and/or 'b'"):
        IdentifyRequest(motors=motors)


def test_feedback_response_takes_points_of_any_shape() -> None:
    ss = controller_state_space("pi", {"kp": 0.4, "ki": 3.0}, 0.01)
    z = np.exp(2j * np.pi * np.array([[0.5, 2.0], [7.0, 20.0]]) * 0.01)
    flat = ss.feedback_response(z.ravel())
    assert np.allclose(ss.feedback_response(z), flat.reshape(2, 2))
    assert np.allclose(ss.feedback_response(z[0, 0]), flat[0])
    assert np.allclose(ss.feedback_response(list(z[1])), flat[2:])
    # a PI's C_fb(z) = g + q / (z − 1) with g = kp + ki Ts, q = ki Ts
    g, q = 0.4 + 3.0 * 0.01, 3.0 * 0.01
    assert np.allclose(flat, g + q / (z.ravel() - 1.0))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy's, from the old fit of inf − inf
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_validate_on_a_trace_with_a_non_finite_speed_gives_a_nan_fit(bad: float) -> None:
    # the Python API takes a Trace as it is (the CSV reader refuses such values): the fit is NaN,
    # as before the one simulation fit, not identification's 'experiment 1 holds NaN' refusal
    from cartctl.identification.validate import validate
    from cartctl.model import ArxModel

    model = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751], na=2, nb=2, nk=2)
    trace = _trace(400)
    speed = trace.speed("a").copy()
    speed[100] = bad
    z = np.zeros(speed.size)
    odd = Trace(trace.time_s, trace.voltage("a"), z, speed, z, source="odd.csv")
    result = validate(model, odd, "a")
    assert math.isnan(result.fit_simulation_percent)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_fit_oe_on_fewer_samples_than_parameters_is_an_identification_error() -> None:
    # the Python API: 3 samples for 4 parameters is identification's 'too few samples', as before
    # the one θ covariance (whose R of the Jacobian is then wide: not a ValueError 'expected
    # square matrix')
    from cartctl.identification.arx import IdentificationError
    from cartctl.identification.oe import fit_oe
    from cartctl.model import ArxModel

    model = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751], na=2, nb=2, nk=2)
    u = np.array([6.0, -6.0, 6.0])
    with pytest.raises(IdentificationError, match="too few samples"):
        fit_oe([(model.simulate(u) + 0.01, u)], model)
