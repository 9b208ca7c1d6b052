"""Settling in run and review summaries: band max(2 %, one encoder count per tick), judged on the
true speed where the trace has one, else on the measured speed; hand-made traces with known
answers, through ``trace_metrics`` and through ``cartctl review RUN.csv``."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from cartctl.cart import encoder_quantum_rad_s
from cartctl.cli import main
from cartctl.measures.stepinfo import settling_half_width, step_info
from cartctl.sinks.base import TRACE_COLUMNS, TRUE_SPEED_COLUMNS
from cartctl.sinks.summary import format_summary, trace_metrics

TS = 0.01
N = 300
K0 = 50  # the reference steps at tick 50, t = 0.5 s
QUANTUM = 2 * math.pi / 1792 / TS  # one encoder count per tick


def _columns(reference: float, true: np.ndarray, measured: np.ndarray) -> dict[str, np.ndarray]:
    """A closed-loop trace of both motors (the same signals on each) with true speeds."""
    k = np.arange(N, dtype=float)
    ref = np.where(k >= K0, reference, 0.0)
    zeros = np.zeros(N)
    return {
        "time_s": k * TS,
        "voltage_a": zeros + 1.0,
        "voltage_b": zeros + 1.0,
        "speed_a": measured,
        "speed_b": measured,
        "tick": k,
        "reference_a": ref,
        "reference_b": ref,
        "estimate_a": measured,
        "estimate_b": measured,
        "period_error_us": zeros,
        "compute_us": zeros,
        "true_speed_a": true,
        "true_speed_b": true,
    }


def _overshooting_ramp(reference: float, peak: float) -> np.ndarray:
    """0 until K0, a straight line to ``peak`` at K0 + 40, straight down to ``reference`` at
    K0 + 60, then flat: linear between samples, so interpolated crossings are exact."""
    k = np.arange(N, dtype=float)
    up = peak * (k - K0) / 40.0
    down = peak + (reference - peak) * (k - K0 - 40) / 20.0
    return np.select([k < K0, k <= K0 + 40, k <= K0 + 60], [0.0, up, down], reference)


def test_encoder_quantum_and_band() -> None:
    assert encoder_quantum_rad_s(0.01) == pytest.approx(0.350624, abs=1e-6)  # 2π / 1792 / 0.01
    assert settling_half_width(5.0, QUANTUM) == pytest.approx(QUANTUM)  # 2 % = 0.1 < q
    assert settling_half_width(-20.0, QUANTUM) == pytest.approx(0.4)  # 2 % = 0.4 > q
    assert settling_half_width(20.0) == pytest.approx(0.4)


def test_step_info_floor_widens_the_band_for_small_steps() -> None:
    t = np.arange(100) * TS
    y = np.minimum(t / 0.5, 1.0) * 5.0  # a ramp to 5 rad/s in 0.5 s, then flat
    plain = step_info(t, y, reference=5.0)
    floored = step_info(t, y, reference=5.0, settling_floor=QUANTUM)
    assert plain.settling_time_s == pytest.approx(0.5 * 0.98)
    assert floored.settling_time_s == pytest.approx(0.5 * (1 - QUANTUM / 5.0))
    tiny = step_info(t, y / 50.0, reference=0.1, settling_floor=QUANTUM)  # step inside its band
    assert tiny.settling_time_s is None


def test_small_step_settles_in_the_encoder_band_on_the_true_speed() -> None:
    r, peak = 5.0, 5.25  # 5 % overshoot; band max(0.1, 0.3506) = 0.3506 rad/s
    true = _overshooting_ramp(r, peak)
    measured = true.copy()
    measured[K0 + 100] += 1.0  # an encoder glitch at t = 1.5 s, on the measured speed only
    summary = trace_metrics(_columns(r, true, measured), TS)
    assert summary["metrics_signal"] == "true_speed"
    for motor in ("a", "b"):
        e = summary["motors"][motor]
        # up the ramp into the band: 5.25 (k − K0)/40 = 5 − q; the peak 5.25 < 5 + q stays inside
        assert e["settling_time_s"] == pytest.approx(40 * (r - QUANTUM) / peak * TS, abs=1e-12)
        assert e["overshoot_percent"] == pytest.approx(5.0)
        assert e["steady_state_error"] == pytest.approx(0.0, abs=1e-12)
    text = format_summary(summary)
    assert "tracking on the true speed" in text
    assert "max(2 %, 0.351 rad/s)" in text  # 0.3506 rad/s to three significant figures


def test_without_true_speed_the_measured_speed_is_judged() -> None:
    r, peak = 5.0, 5.25
    true = _overshooting_ramp(r, peak)
    measured = true.copy()
    measured[K0 + 100] += 1.0  # 6.0 at t = 1.5 s, back to 5.0 at 1.51 s
    columns = _columns(r, true, measured)
    for name in TRUE_SPEED_COLUMNS:
        del columns[name]
    summary = trace_metrics(columns, TS)
    assert summary["metrics_signal"] == "speed"
    e = summary["motors"]["a"]
    # leaves the band at the glitch, back in where 6 → 5 crosses 5 + q: 1.5 s + (1 − q) ticks
    assert e["settling_time_s"] == pytest.approx(1.5 + (1.0 - QUANTUM) * TS - 0.5, abs=1e-12)
    assert e["overshoot_percent"] == pytest.approx(20.0)  # the same signal: (6 − 5) / 5
    assert "tracking on the measured speed" in format_summary(summary)


def test_large_step_keeps_the_two_percent_band() -> None:
    r = 20.0  # 2 % = 0.4 rad/s > q
    true = _overshooting_ramp(r, r)  # straight up to 20 at K0 + 40, no overshoot
    e = trace_metrics(_columns(r, true, true), TS)["motors"]["a"]
    assert e["settling_time_s"] == pytest.approx(40 * 0.98 * TS, abs=1e-12)
    assert e["overshoot_percent"] == 0.0


def test_review_of_the_csv_gives_the_same_numbers(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    r, peak = 5.0, 5.25
    true = _overshooting_ramp(r, peak)
    measured = true.copy()
    measured[K0 + 100] += 1.0
    columns = _columns(r, true, measured)
    path = tmp_path / "run.csv"
    names = TRACE_COLUMNS + TRUE_SPEED_COLUMNS
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for i in range(N):
            writer.writerow([repr(float(columns[c][i])) for c in names])
    assert main(["review", str(path), "--json"]) == 0
    review = json.loads(capsys.readouterr().out)
    assert review["metrics_signal"] == "true_speed"
    a = review["motors"]["a"]
    assert a["settling_time_s"] == pytest.approx(40 * (r - QUANTUM) / peak * TS, abs=1e-9)
    assert a["overshoot_percent"] == pytest.approx(5.0)
