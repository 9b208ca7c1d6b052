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


def test_a_trace_begun_after_the_step_has_no_step_metrics(tmp_path, capsys) -> None:
    """A monitor started while the cart already held its reference (the usual way to watch a
    cart running its own controller) holds no step from rest: dashes, not a 0 ms rise and
    settling, nor the encoder's ripple as overshoot. A step from rest at row 0 keeps them."""
    import json

    from cartctl.cli import main

    n = 100
    ripple = 8.0 + 0.35 * (np.arange(n) % 3 == 0)  # whole encoder counts around 8 rad/s
    rows = ["time_s,tick,speed_a,speed_b,voltage_a,voltage_b,reference_a,reference_b"]
    rows += [f"{k * 0.01:.2f},{k},{ripple[k]},{ripple[k]},4.6,4.6,8.0,8.0" for k in range(n)]
    (tmp_path / "m.csv").write_text("\n".join(rows) + "\n")
    assert main(["review", str(tmp_path / "m.csv"), "--json"]) == 0
    a = json.loads(capsys.readouterr().out)["motors"]["a"]
    assert a["overshoot_percent"] is a["rise_time_s"] is a["settling_time_s"] is None
    assert a["rms_error"] == pytest.approx(np.sqrt(np.mean((8.0 - ripple) ** 2)))
    t = np.arange(n) * 0.01
    from_rest = motor_metrics(t, np.full(n, 8.0), 8.0 * (1 - np.exp(-t / 0.03)), np.ones(n))
    assert from_rest["rise_time_s"] == pytest.approx(0.03 * np.log(9), abs=0.003)
