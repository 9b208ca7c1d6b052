"""sinks.summary on inputs the commands never pass but the API takes."""

from __future__ import annotations

import numpy as np
import pytest

from cartctl.errors import InputError
from cartctl.sinks.summary import motor_metrics


def test_motor_metrics_of_no_speed_is_an_input_error() -> None:
    t = np.arange(5) * 0.01
    with pytest.raises(InputError, match="equal length"):
        motor_metrics(t, np.ones(5), np.zeros(0), np.ones(5))


def test_motor_metrics_of_no_voltage() -> None:
    t = np.arange(5) * 0.01
    out = motor_metrics(t, np.ones(5), np.ones(5), np.zeros(0))
    assert out["max_abs_voltage"] is None and out["rms_error"] == 0.0
