"""Step-response metrics: agreement with python-control, invariances, undefined metrics, errors."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import control
import numpy as np
import pytest

from cartctl.cli import main
from cartctl.errors import InputError
from cartctl.measures.stepinfo import StepOnset, final_value, find_step, step_info

TS = 0.01
T = np.arange(400) * TS

# Discrete systems whose step response has settled well before the end of T, so that the final
# value (mean of the last 5 %) equals python-control's (the DC gain) to rounding.
SYSTEMS = {
    "first order": ([0.2], [1.0, -0.8]),
    "underdamped": ([0.05], np.poly([0.9 + 0.2j, 0.9 - 0.2j]).real),
    "ground model a (nk = 2)": ([0.6466, -0.07751], [1.0, -0.9356, 0.2173, 0.0]),
    "negative gain": ([-0.5], [1.0, -0.5]),
    "non-minimum phase": ([-0.3, 0.5], [1.0, -0.8, 0.0]),
}


def _response(num: list[float], den: np.ndarray | list[float]) -> tuple[object, np.ndarray]:
    sys = control.tf(num, den, TS)
    return sys, control.step_response(sys, T).outputs


@pytest.mark.parametrize("name", SYSTEMS)
def test_sample_times_agree_with_python_control(name: str) -> None:
    # Where the definitions agree: with the DC gain as reference, no interpolation and the
    # onset at t = 0, rise, settling, overshoot and peak are python-control's exactly.
    sys, y = _response(*SYSTEMS[name])
    theirs = control.step_info(sys, T)
    ours = step_info(T, y, reference=control.dcgain(sys), interpolate=False)
    assert ours.rise_time_s == pytest.approx(theirs["RiseTime"], abs=1e-12)
    assert ours.settling_time_s == pytest.approx(theirs["SettlingTime"], abs=1e-12)
    assert ours.overshoot_percent == pytest.approx(theirs["Overshoot"], abs=1e-9)
    assert abs(ours.peak_value) == pytest.approx(theirs["Peak"], rel=1e-12)
    if theirs["Overshoot"] > 0:  # a monotone response's "peak" is a rounding tie
        assert ours.peak_time_s == pytest.approx(theirs["PeakTime"], abs=1e-12)
    assert ours.steady_state_value == pytest.approx(theirs["SteadyStateValue"], rel=1e-9)
    assert ours.steady_state_error == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("name", SYSTEMS)
def test_interpolated_times_lie_within_one_sample(name: str) -> None:
    sys, y = _response(*SYSTEMS[name])
    theirs = control.step_info(sys, T)
    ours = step_info(T, y)  # final value from the data, interpolated crossings
    assert ours.rise_time_s == pytest.approx(theirs["RiseTime"], abs=TS)
    # interpolation moves the settling instant earlier, never later
    assert theirs["SettlingTime"] - TS <= ours.settling_time_s <= theirs["SettlingTime"]


def test_first_order_rise_time_matches_theory() -> None:
    # y[k] = 1 − 0.8^k reaches the fraction f at k = ln(1 − f) / ln 0.8 (continuous k)
    y = 1.0 - 0.8 ** np.arange(200)
    info = step_info(np.arange(200) * TS, y, reference=1.0)
    k10, k90 = (np.log(1 - f) / np.log(0.8) for f in (0.1, 0.9))
    assert info.rise_time_s == pytest.approx((k90 - k10) * TS, rel=0.02)
    assert info.settling_time_s == pytest.approx(np.log(0.02) / np.log(0.8) * TS, rel=0.02)
    assert info.overshoot_percent == 0.0


def test_negative_step_mirrors_positive() -> None:
    _, y = _response(*SYSTEMS["underdamped"])
    up = step_info(T, y, reference=1.0, initial=0.0)
    down = step_info(T, -y, reference=-1.0)
    assert down.rise_time_s == pytest.approx(up.rise_time_s)
    assert down.settling_time_s == pytest.approx(up.settling_time_s)
    assert down.overshoot_percent == pytest.approx(up.overshoot_percent)
    assert down.peak_value == pytest.approx(-up.peak_value)
    assert down.step_size == pytest.approx(-up.step_size)


def test_offset_and_onset_shift_change_nothing_but_the_values() -> None:
    _, y = _response(*SYSTEMS["underdamped"])
    base = step_info(T, y)
    # the same response starting from 5, and applied 0.5 s later, after 0.5 s at rest
    pad = np.full(50, 5.0)
    t2 = np.arange(400 + 50) * TS
    shifted = step_info(t2, np.concatenate([pad, y + 5.0]), initial=5.0, onset_s=0.5)
    assert shifted.rise_time_s == pytest.approx(base.rise_time_s)
    assert shifted.settling_time_s == pytest.approx(base.settling_time_s)
    assert shifted.peak_time_s == pytest.approx(base.peak_time_s)
    assert shifted.overshoot_percent == pytest.approx(base.overshoot_percent)
    assert shifted.peak_value == pytest.approx(base.peak_value + 5.0)


def test_settling_counts_from_the_onset() -> None:
    t = np.arange(100) * TS
    y = np.where(t >= 0.3, 1.0, 0.0)  # an ideal step at 0.3 s
    info = step_info(t, y, onset_s=0.3, interpolate=False)
    assert info.settling_time_s == pytest.approx(0.0)
    assert info.rise_time_s == pytest.approx(0.0)


def test_steady_state_error_against_a_reference() -> None:
    y = 0.8 * (1.0 - 0.5 ** np.arange(100))
    info = step_info(np.arange(100) * TS, y, reference=1.0)
    assert info.steady_state_error == pytest.approx(0.2)
    assert info.step_size == 1.0
    assert info.rise_time_s is None  # 0.8 never reaches 90 % of the reference
    assert info.settling_time_s is None  # nor the 2 % band around it
    assert step_info(np.arange(100) * TS, y).steady_state_error is None


def test_unsettled_response_has_no_settling_time() -> None:
    t = np.arange(300) * TS
    y = 1.0 + 0.5 * np.sin(2 * np.pi * 2.0 * t) * (t > 0.05)  # rings for ever
    info = step_info(t, y, reference=1.0, initial=0.0)
    assert info.settling_time_s is None
    assert info.overshoot_percent == pytest.approx(50.0, rel=0.01)


def test_flat_tail_has_no_overshoot() -> None:
    y = np.minimum(np.arange(50) * 0.37, 7.3)  # ramps up, then flat: no rounding overshoot
    assert step_info(np.arange(50) * TS, y).overshoot_percent == 0.0


def test_to_dict_has_contract_names() -> None:
    d = step_info(T, _response(*SYSTEMS["first order"])[1]).to_dict()
    assert {"rise_time_s", "settling_time_s", "overshoot_percent"} <= set(d)
    assert {"peak_value", "peak_time_s", "steady_state_value", "steady_state_error"} <= set(d)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"time_s": T, "response": np.zeros(400)}, "size zero"),
        ({"time_s": T, "response": np.ones(400), "initial": 1.0}, "size zero"),
        ({"time_s": T, "response": np.ones(400), "reference": 0.0}, "size zero"),
        ({"time_s": T, "response": np.ones(399)}, "equal length"),
        ({"time_s": T[:1], "response": np.ones(1)}, "two samples"),
        ({"time_s": T[::-1], "response": np.ones(400)}, "increase"),
        ({"time_s": T, "response": np.full(400, np.nan)}, "finite"),
        ({"time_s": T, "response": np.ones(400), "onset_s": 9.0}, "outside"),
        ({"time_s": T, "response": np.ones(400), "settling_band": 0.0}, "band"),
    ],
)
def test_bad_input_raises_input_error(kwargs: dict, message: str) -> None:
    with pytest.raises(InputError, match=message):
        step_info(**kwargs)


def test_final_value_averages_the_last_five_percent() -> None:
    y = np.concatenate([np.zeros(190), np.arange(10.0)])
    assert final_value(y) == pytest.approx(np.mean(np.arange(10.0)))  # ceil(0.05 * 200) = 10
    assert final_value(np.arange(20.0)) == pytest.approx(17.0)  # at least 5 samples
    assert final_value([3.0, 4.0]) == pytest.approx(3.5)  # all, if fewer


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        ([0, 0, 0, 10, 10, 10], StepOnset(3, 10.0)),
        ([-7, -7, -7], StepOnset(0, -7.0)),  # the record starts at the step
        ([0, 0, 0], None),  # no step
        ([0, 10, 10, 0], None),  # a pulse
        ([0, 3, 10, 10], None),  # two steps
    ],
)
def test_find_step(values: list[float], expected: StepOnset | None) -> None:
    assert find_step(np.asarray(values, dtype=float)) == expected


def test_final_value_ignores_the_samples_before_a_late_onset() -> None:
    # A step at 4.8 s of a 5 s record: the last 5 % of the record (26 samples) would reach back
    # before the onset and average the zeros there in; the final value is the mean of the last
    # 5 % (at least 5 samples) of the response from its onset on.
    t = np.arange(501) * TS
    y = np.where(t >= 4.8 - 1e-9, 10.0, 0.0)
    info = step_info(t, y, reference=10.0, onset_s=4.8)
    assert info.steady_state_value == pytest.approx(10.0)
    assert info.steady_state_error == pytest.approx(0.0, abs=1e-12)
    # without a reference the final value is the target: a clean step, 100 % at once
    info = step_info(t, y, onset_s=4.8, interpolate=False)
    assert info.step_size == pytest.approx(10.0)
    assert info.overshoot_percent == 0.0


def test_run_summary_of_a_late_step_against_python_control(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The shipped PI on the sim plant (the ground model, the loop C·G), a 10 rad/s step 0.2 s
    # before the end of a 5 s run: the steady-state error is the reference minus the mean of the
    # last 5 samples after the onset (21 of them), here from python-control's closed loop.
    root = Path(__file__).resolve().parents[1]
    pi = tomllib.loads((root / "controllers" / "pi.toml").read_text(encoding="utf-8"))
    ground = tomllib.loads((root / "models" / "ground.toml").read_text(encoding="utf-8"))
    args = ["run", "--plant", "sim", "--reference", "step:10:4.8", "--duration", "5", "--fast"]
    args += ["--rerun", "off", "--out", str(tmp_path), "--json"]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    for m in ("a", "b"):
        c, d, a, b = ground["motors"][m]["theta"]
        kp, ki = pi["motors"][m]["kp"], pi["motors"][m]["ki"]
        loop = control.tf([kp + ki * TS, -kp], [1.0, -1.0], TS) * control.tf(
            [a, b], [1, c, d, 0], TS
        )
        y = control.step_response(10.0 * control.feedback(loop, 1), np.arange(21) * TS).outputs
        expected = 10.0 - float(np.mean(y[-5:]))
        assert summary["motors"][m]["steady_state_error"] == pytest.approx(expected, abs=1e-9)
