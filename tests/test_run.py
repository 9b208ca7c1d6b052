"""``cartctl run`` end to end: trace, recording, summary against review, Ctrl-C, real time."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from cartctl.cli import main
from cartctl.data.read import read_trace
from cartctl.plants import factory
from cartctl.plants.sim import ArxPlant

ROOT = Path(__file__).resolve().parents[1]
CONTRACT_PATHS = [
    f"motor/{m}/{s}" for m in "ab" for s in ("reference", "speed", "estimate", "voltage")
]
CONTRACT_PATHS += ["loop/period_error_us", "loop/compute_us"]


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict | str, str]:
    code = main(["run", *argv])
    out, err = capsys.readouterr()
    try:
        return code, json.loads(out), err
    except json.JSONDecodeError:
        return code, out, err


def test_fast_run_records_trace_and_the_rerun_entity_paths(
    capsys: pytest.CaptureFixture[str], workdir: Path, rrd_rows
) -> None:
    code, summary, err = _run(
        capsys, "--fast", "--duration", "3", "--rerun", "save", "--json", "--name", "r"
    )
    assert code == 0, err
    assert isinstance(summary, dict)
    assert summary["ticks"] == 301  # 300 ticks of control and the stop row
    assert summary["deadline_misses"] == 0
    assert summary["loop_delay_ticks"] == 1  # models/ground.toml: nk = 2, loop delay nk − 1
    trace = read_trace(summary["trace"])
    assert len(trace) == 301
    assert trace.column("tick")[-1] == 300 and trace.voltage_a[-1] == 0.0
    rows = rrd_rows(Path(summary["recording"]))
    for path in CONTRACT_PATHS:
        assert rows[path] == 301, path
    a = summary["motors"]["a"]
    assert a["overshoot_percent"] <= 5.0
    assert abs(a["steady_state_error"]) < 1e-6
    assert a["max_abs_voltage"] <= 12.0
    assert set(a) == {"overshoot_percent", "settling_time_s", "rise_time_s", "steady_state_error",
                      "rms_error", "max_abs_voltage"}  # fmt: skip


def test_summary_step_metrics_equal_review_of_the_csv(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    code, summary, _ = _run(capsys, "--fast", "--duration", "2", "--plant", "physics", "--rerun", "off",
                            "--controller", "controllers/poles.toml", "--json")  # fmt: skip
    assert code == 0
    assert summary["recording"] is None
    assert main(["review", summary["trace"], "--json"]) == 0
    review = json.loads(capsys.readouterr().out)
    # by hand from the trace's columns (csv module, numpy): the error, the peak, the overshoot
    import csv

    with open(summary["trace"], newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    col = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    for m in "ab":
        ref, true = col[f"reference_{m}"], col[f"true_speed_{m}"]
        entry = review["motors"][m]
        assert entry["rms_error"] == pytest.approx(np.sqrt(np.mean((ref - true) ** 2)), rel=1e-9)
        assert entry["max_abs_voltage"] == pytest.approx(np.max(np.abs(col[f"voltage_{m}"])))
        step = ref > 0
        peak = np.max(true[step])
        assert entry["overshoot_percent"] == pytest.approx(max(0.0, (peak - 10.0) / 10.0 * 100))
        assert summary["motors"][m]["rms_error"] == pytest.approx(entry["rms_error"], rel=1e-12)


def test_ctrl_c_leaves_zero_volts_and_readable_files(
    capsys: pytest.CaptureFixture[str], workdir: Path, monkeypatch: pytest.MonkeyPatch, rrd_rows
) -> None:
    sent: list[tuple[float, float]] = []

    class Interrupting(ArxPlant):
        def step(self, voltage_a_v: float, voltage_b_v: float):
            sent.append((voltage_a_v, voltage_b_v))
            if len(sent) == 150:
                raise KeyboardInterrupt
            return super().step(voltage_a_v, voltage_b_v)

    original = factory.make_plant

    def fake_make_plant(*args, **kwargs):
        plant, _ = original(*args, **kwargs)
        return Interrupting(*plant.models), "interrupting sim"

    monkeypatch.setattr(factory, "make_plant", fake_make_plant)
    code, _out, err = _run(capsys, "--fast", "--duration", "5", "--rerun", "save", "--name", "cut")
    assert code == 130
    assert "interrupted" in err
    assert sent[-1] == (0.0, 0.0)
    assert max(abs(v) for v in sent[-2]) > 0.0  # it was driving when cut
    trace = read_trace(workdir / "logs" / "cut.csv")
    assert len(trace) == 150  # 149 ticks, then the stop row (tick 149's command was 0 V)
    assert trace.voltage_a[-1] == 0.0 and trace.voltage_a[-2] != 0.0
    rows = rrd_rows(workdir / "logs" / "cut.rrd")
    assert rows["motor/a/speed"] == 150
    RrdReader(
        workdir / "logs" / "cut.rrd"
    ).store()  # needs the footer: the file was closed properly


@pytest.mark.realtime
def test_short_real_time_run(capsys: pytest.CaptureFixture[str], workdir: Path) -> None:
    """Real time on a shared machine: every tick runs, on the wall clock (never sooner), and the
    timing figures are reported; how good they are is the benchmarks' (``benchmarks/bench_run.py``)."""
    code, summary, err = _run(capsys, "--duration", "1", "--rerun", "save", "--json")
    assert code == 0, err
    assert summary["ticks"] == 101
    assert summary["duration_s"] >= 0.99  # 100 periods of 10 ms after tick 0
    assert 0 <= summary["deadline_misses"] <= summary["ticks"]
    timing = summary["period_error_us"]
    assert 0.0 <= timing["p50"] <= timing["p99"] <= timing["max"]
    assert Path(summary["recording"]).is_file()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--controller", "nope.toml"], "controller file not found: nope.toml"),
        (["--reference", "sine:3"], "unknown reference 'sine:3'"),
        (["--duration", "-1"], "--duration"),
        (["--voltage-limit", "20"], "--voltage-limit"),
        (["--plant", "moon"], "'moon'"),
    ],
)
def test_user_mistakes(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: list[str], message: str
) -> None:
    code, _out, err = _run(capsys, "--fast", *argv)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert not (workdir / "logs").exists() or not any((workdir / "logs").iterdir())


def test_runs_do_not_overwrite_each_other(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    traces = set()
    for _ in range(2):
        code, summary, _ = _run(capsys, "--fast", "--duration", "0.5", "--rerun", "off", "--json")
        assert code == 0
        traces.add(summary["trace"])
    assert len(traces) == 2


def test_a_run_without_recording_removes_an_earlier_recording_of_its_name(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    """``--rerun off`` over an earlier run of the same --name left that run's X.rrd beside the
    new X.csv: ``review X.rrd`` showed the old run as this one's."""
    code, _, err = _run(capsys, "--fast", "--duration", "0.5", "--rerun", "save", "--name", "x")
    assert code == 0, err
    assert (workdir / "logs" / "x.rrd").is_file()
    code, summary, err = _run(capsys, "--fast", "--duration", "0.3", "--rerun", "off", "--json",
                              "--name", "x")  # fmt: skip
    assert code == 0, err
    assert summary["recording"] is None
    assert not (workdir / "logs" / "x.rrd").exists()


def test_trace_has_one_row_per_tick_with_true_speed(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    code, summary, _ = _run(
        capsys, "--fast", "--duration", "1", "--plant", "physics", "--rerun", "off", "--json"
    )
    assert code == 0
    trace = read_trace(summary["trace"])
    np.testing.assert_allclose(np.diff(trace.time_s), 0.01)
    assert "true_speed_a" in trace.columns()


def test_a_one_motor_controller_holds_the_other_motor_at_rest(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    # it asked motor b for 10 rad/s it never drove, and reported 10 rad/s of steady-state error
    code = main(["design", "models/ground.toml", "--method", "pi", "--motor", "a",
                 "--out", "a-only.toml"])  # fmt: skip
    assert code == 0
    capsys.readouterr()
    code, summary, err = _run(capsys, "--fast", "--controller", "a-only.toml", "--duration", "1",
                              "--rerun", "off", "--json", "--name", "one")  # fmt: skip
    assert code == 0, err
    assert isinstance(summary, dict)
    trace = read_trace(summary["trace"])
    assert np.all(trace.column("reference_b") == 0.0) and np.all(trace.voltage_b == 0.0)
    assert trace.column("reference_a")[-2] == 10.0  # the last row is the stop row
    b = summary["motors"]["b"]
    assert b["steady_state_error"] is None and b["rms_error"] == 0.0
    code, _, err = _run(capsys, "--fast", "--controller", "a-only.toml", "--reference-b", "step:3",
                        "--rerun", "off")  # fmt: skip
    assert code == 2 and err.strip().splitlines() == [
        "cartctl run: error: --reference-b: a-only.toml has no controller for motor b"
    ]
