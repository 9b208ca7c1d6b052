"""``cartctl tune``: grid specs, the Pareto front on fixed numbers, and a small grid run end to end
against ``cartctl run --fast`` and ``cartctl design``."""

from __future__ import annotations

import contextlib
import io
import json
import math
import shlex
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cartctl.cli import build_parser as main_parser
from cartctl.cli import main
from cartctl.cli.commands.design import request_from_args
from cartctl.data.modelfile import load_models
from cartctl.data.read import read_trace
from cartctl.design.analysis import simulate_step
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.errors import InputError
from cartctl.measures.stepinfo import step_info
from cartctl.tune.engine import TuneJob, scoring_plant
from cartctl.tune.grid import (
    TuneResult,
    design_request,
    grid_settings,
    mark_pareto,
    pareto_front,
    parse_grid,
    request_axes,
)

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
# 60° at 2 Hz needs Kp < 0 on the ground model (infeasible); 4 Hz works for both margins.
PI_GRID = "phase_margin=60:65:5,crossover_hz=2:4:2"
CHOSEN = 4  # 65°, 4 Hz (the first axis varies slowest)
QUANTUM = 2 * math.pi / 1792 / 0.01  # one encoder count per 10 ms tick (rad/s)


def _motor(overshoot: float | None, settling: float | None, rms: float, peak: float) -> dict:
    return {"overshoot_percent": overshoot, "settling_time_s": settling, "rms_error": rms,
            "max_abs_voltage": peak}  # fmt: skip


@pytest.mark.parametrize(
    ("points", "expected"),
    [
        (
            [
                [1.0, 1.0, 1.0, 1.0],  # dominated by the next two
                [2.0, 2.0, 2.0, 2.0],  # dominated by everything but the NaN row
                [0.0, 5.0, 1.0, 1.0],  # best first column
                [1.0, 1.0, 1.0, 0.5],  # dominates row 0
                [1.0, 1.0, 1.0, 0.5],  # equal rows do not dominate each other
                [math.nan, 0.0, 0.0, 0.0],  # undefined: off the front, dominates nothing
                [3.0, 0.5, 9.0, 9.0],  # best second column
            ],
            [False, False, True, True, True, False, True],
        ),
        ([[5.0, 5.0]], [True]),
        (np.zeros((0, 4)), []),
    ],
)
def test_pareto_front_on_fixed_numbers(points: Any, expected: list[bool]) -> None:
    assert pareto_front(points).tolist() == expected


def test_mark_pareto_uses_the_worse_motor_and_skips_unsettled_and_infeasible() -> None:
    results = [
        TuneResult(1, {"x": 1.0}, True, motors={"a": _motor(1.0, 0.10, 1.0, 5.0),
                                                 "b": _motor(0.0, 0.30, 1.0, 5.0)}),  # worst: 1 %, 0.3 s
        TuneResult(2, {"x": 2.0}, True, motors={"a": _motor(2.0, 0.20, 1.0, 5.0),
                                                 "b": _motor(2.0, 0.20, 1.0, 5.0)}),  # 2 %, 0.2 s
        TuneResult(3, {"x": 3.0}, True, motors={"a": _motor(3.0, 0.25, 1.0, 5.0),
                                                 "b": _motor(3.0, 0.25, 1.0, 5.0)}),  # dominated by 2
        TuneResult(4, {"x": 4.0}, True, motors={"a": _motor(0.0, None, 0.1, 1.0),
                                                 "b": _motor(0.0, 0.01, 0.1, 1.0)}),  # never settled
        TuneResult(5, {"x": 5.0}, False, "refused"),
    ]  # fmt: skip
    assert [r.pareto for r in mark_pareto(results)] == [True, True, False, False, False]
    assert results[0].worst == {"overshoot_percent": 1.0, "settling_time_s": 0.3,
                                "rms_error": 1.0, "max_abs_voltage": 5.0}  # fmt: skip


@pytest.mark.parametrize(
    ("spec", "method", "expected"),
    [
        ("phase_margin=50:60:5", "pi", {"phase-margin": (50.0, 55.0, 60.0),
                                        "crossover-hz": (2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0)}),
        ("phase-margin=50:60:5", "pi", {"phase-margin": (50.0, 55.0, 60.0),
                                        "crossover-hz": (2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0)}),
        (" crossover_hz = 2:2.3:0.1 , phase_margin=70", "pi",
         {"phase-margin": (70.0,), "crossover-hz": (2.0, 2.1, 2.2, 2.3)}),
        ("crossover-hz=2:2.3:0.1,phase_margin=70", "pi",
         {"phase-margin": (70.0,), "crossover-hz": (2.0, 2.1, 2.2, 2.3)}),
        ("overshoot=1", "poles", {"settling-time": (0.04, 0.06, 0.08, 0.1, 0.12, 0.14, 0.16),
                                  "overshoot": (1.0,)}),
        ("settling-time=0.05,overshoot=1", "poles", {"settling-time": (0.05,),
                                                     "overshoot": (1.0,)}),
    ],
)  # fmt: skip
def test_grid_specs(spec: str, method: str, expected: dict) -> None:
    axes = parse_grid(spec, method)
    assert axes == expected
    assert len(grid_settings(axes)) == math.prod(len(v) for v in expected.values())


@pytest.mark.parametrize(
    "spec",
    ["phase_margin=50-75", "phase_margin=50:40:5", "phase_margin=50:60:0", "margin=1",
     "phase_margin=a:b:c", "phase_margin=1:2", "phase_margin=60,phase_margin=65",
     "settling_time=0.1", "phase_margin=nan", "phase_margin=1:100000:0.001",
     "phase-margin=60,phase_margin=65", "phase_margin_deg=60", "--phase-margin=60"],
)  # fmt: skip
def test_bad_grid_specs_are_refused(spec: str) -> None:
    with pytest.raises(InputError, match="--grid"):
        parse_grid(spec, "pi")


def test_bad_grid_spec_on_the_command_line_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code = main(["tune", str(GROUND), "--method", "pi", "--grid", "phase_margin=50..75"])
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith("cartctl tune: error: --grid") and "START:STOP:STEP" in err


def test_a_setting_is_a_design_request_and_its_design_command() -> None:
    request = design_request("pi", {"phase-margin": 65.0, "crossover-hz": 3.5}, 1)
    assert (request.phase_margin_deg, request.crossover_hz, request.extra_delay_ticks) == (
        65,
        3.5,
        1,
    )
    argv = request.to_argv("m.toml", always=request_axes("pi"))
    assert argv == ["m.toml", "--method", "pi", "--phase-margin", "65", "--crossover-hz", "3.5",
                    "--extra-delay", "1"]  # fmt: skip
    # the command parses back to the same request
    parsed = main_parser().parse_args(["design", *argv])
    assert request_from_args(parsed) == request


@pytest.fixture(scope="module")
def tuned(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """One 2×2 PI grid, 1 s runs, two workers, with --json, --plot and --choose/--out."""
    tmp = tmp_path_factory.mktemp("tune")
    out, plot = tmp / "chosen.toml", tmp / "tune.png"
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["tune", str(GROUND), "--method", "pi", "--grid", PI_GRID, "--duration", "1",
                     "--jobs", "2", "--plot", str(plot), "--choose", str(CHOSEN), "--out", str(out),
                     "--json"])  # fmt: skip
    assert code == 0
    return {"doc": json.loads(stdout.getvalue()), "out": out, "plot": plot, "tmp": tmp}


def test_json_has_one_row_per_setting_and_reports_infeasible_ones(tuned: dict[str, Any]) -> None:
    doc = tuned["doc"]
    assert doc["method"] == "pi"
    rows = {r["index"]: r for r in doc["settings"]}
    assert sorted(rows) == [1, 2, 3, 4]
    assert {(r["settings"]["phase-margin"], r["settings"]["crossover-hz"]) for r in rows.values()} == {
        (60.0, 2.0), (60.0, 4.0), (65.0, 2.0), (65.0, 4.0)}  # fmt: skip
    assert not rows[1]["feasible"] and "crossover must lie between" in rows[1]["reason"]
    assert rows[1]["overshoot_percent"] is None and not rows[1]["pareto"]
    assert rows[4]["feasible"] and rows[4]["reason"] is None
    keys = ("overshoot_percent", "settling_time_s", "rms_error", "peak_voltage_v")
    front = pareto_front(
        [[math.nan if r[k] is None else r[k] for k in keys] for r in doc["settings"]]
    )
    assert [r["pareto"] for r in doc["settings"]] == front.tolist()
    assert doc["settings"][-1]["feasible"] is False  # the infeasible sort last


def test_tuned_metrics_equal_those_of_run_fast_with_the_chosen_controller(
    tuned: dict[str, Any],
) -> None:
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["run", "--fast", "--controller", str(tuned["out"]), "--model", str(GROUND),
                     "--duration", "1", "--rerun", "off", "--out", str(tuned["tmp"]), "--json"])  # fmt: skip
    assert code == 0
    summary = json.loads(stdout.getvalue())
    run_motors = summary["motors"]
    row = next(r for r in tuned["doc"]["settings"] if r["index"] == CHOSEN)
    # tune's figures, by hand from the trace `run --fast` wrote for the chosen file
    columns = read_trace(summary["trace"]).columns()
    for m in ("a", "b"):
        ref, speed = columns[f"reference_{m}"], columns[f"speed_{m}"]
        got = row["motors"][m]
        assert got["rms_error"] == pytest.approx(np.sqrt(np.mean((ref - speed) ** 2)), rel=1e-9)
        assert got["max_abs_voltage"] == pytest.approx(np.max(np.abs(columns[f"voltage_{m}"])))
        peak = np.max(speed[ref > 0])
        assert got["overshoot_percent"] == pytest.approx(max(0.0, (peak - 10.0) / 10.0 * 100))
    assert row["settling_time_s"] == max(run_motors[m]["settling_time_s"] for m in "ab")
    # settling in the band of the design's bound: one encoder count per tick (0.3506 rad/s) is
    # wider than 2 % of the 10 rad/s step; the run's trace measured so by hand
    for m in ("a", "b"):
        info = step_info(columns["time_s"], columns[f"speed_{m}"], reference=10.0, onset_s=0.5,
                         settling_band=QUANTUM / 10.0)  # fmt: skip
        assert row["motors"][m]["settling_time_s"] == pytest.approx(info.settling_time_s, abs=1e-9)


def test_chosen_file_is_what_cartctl_design_writes(tuned: dict[str, Any]) -> None:
    chosen = tuned["doc"]["chosen"]
    assert chosen["index"] == CHOSEN
    assert chosen["command"].startswith("cartctl design ")
    argv = shlex.split(chosen["command"])[1:]
    direct = tuned["tmp"] / "direct.toml"
    argv[argv.index("--out") + 1] = str(direct)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(argv) == 0
    ours, theirs = load_controller(tuned["out"]), load_controller(direct)
    assert ours.command == chosen["command"]
    assert (ours.method, ours.request, ours.motors) == (
        theirs.method,
        theirs.request,
        theirs.motors,
    )
    assert ours.request["phase_margin_deg"] == 65.0 and ours.request["crossover_hz"] == 4.0


def test_plot_is_a_png(tuned: dict[str, Any]) -> None:
    assert tuned["plot"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_poles_table_has_one_row_per_setting(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["tune", str(GROUND), "--method", "poles", "--grid",
                 "settling_time=0.02:0.06:0.04,overshoot=1", "--duration", "1", "--jobs", "1"])  # fmt: skip
    out, _ = capsys.readouterr()
    assert code == 0
    rows = [line for line in out.splitlines() if line[5:9].strip().isdigit()]
    assert len(rows) == 2
    assert rows[0].startswith("*o") and rows[0].endswith("settled")  # the only one that ran
    assert rows[1].endswith("infeasible")
    assert "#1: motor a: settling_time_s must be at least" in out
    assert "2 settings: 1 infeasible request (the design refused it), 0 ran but did not settle, 1 settled" in out  # fmt: skip


def test_choosing_an_infeasible_setting_prints_the_table_then_one_error_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """On PI_GRID, 60° and 65° at 2 Hz need Kp < 0 (a 65° crossover must lie above 2.24 Hz):
    settings #1 and #3 are infeasible requests, #2 and #4 can be chosen."""
    code = main(["tune", str(GROUND), "--method", "pi", "--grid", PI_GRID, "--duration", "0.6",
                 "--jobs", "1", "--choose", "1", "--out", str(tmp_path / "c.toml")])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("cartctl tune: error: --choose 1: ")
    assert "infeasible request" in err and err.rstrip().endswith(
        "settings that can be chosen: 2, 4"
    )
    table = [line for line in out.splitlines() if line[5:9].strip().isdigit()]
    assert sorted(int(line[5:9]) for line in table) == [1, 2, 3, 4]  # the whole table, first
    assert "#1: motor a: a PI cannot give 60° phase margin at 2 Hz" in out
    assert not (tmp_path / "c.toml").exists()


@pytest.mark.parametrize("plant", ["sim", "physics"])
def test_the_scored_plant_has_the_loop_delay_the_design_is_for(plant: str) -> None:
    """--extra-delay 3 on the report's model (nk = 2, loop delay 1): a voltage commanded at tick 0
    first shows in the measurement of tick 2 + 3 = 5, a loop delay of 4; the response is the
    nominal one, three ticks later. On the physics cart the command lands 3 ms into its tick, so
    the speed sample that closes that tick already sees part of it: one tick sooner there."""
    speeds = {}
    for extra in (0, 3):
        p = scoring_plant(TuneJob(str(GROUND), "pi", plant, "ground", "step:10", 1.0, extra, ()))
        p.reset()
        speeds[extra] = np.array([p.step(6.0, 6.0).speed_a_rad_s for _ in range(40)])  # ticks 1..
        p.close()
    first_tick = {extra: int(np.flatnonzero(y)[0]) + 1 for extra, y in speeds.items()}
    first = 2 if plant == "sim" else 1
    assert first_tick == {0: first, 3: first + 3}  # loop delays 1 and 4
    np.testing.assert_array_equal(speeds[3][3:], speeds[0][:-3])


def _tune_json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, Any]:
    code = main(["tune", str(GROUND), "--jobs", "1", "--json", *argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_tuning_with_extra_delay_scores_the_designs_own_loop(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A PI setting tuned with --extra-delay 3 runs as ``cartctl design --extra-delay 3``
    simulates its step (the model with nk + 3), and settles later than with no extra delay."""
    grid = ["--method", "pi", "--grid", "phase_margin=65,crossover_hz=3", "--duration", "1",
            "--reference", "step:10:0"]  # fmt: skip
    rows = {extra: _tune_json(capsys, *grid, "--extra-delay", str(extra))["settings"][0]
            for extra in (0, 3)}  # fmt: skip
    assert rows[0]["feasible"] and rows[3]["feasible"]
    models = load_models(GROUND)
    out = tmp_path / "pi3.toml"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["design", str(GROUND), "--method", "pi", "--phase-margin", "65",
                     "--crossover-hz", "3", "--extra-delay", "3", "--out", str(out)]) == 0  # fmt: skip
    for m, ctrl in build_controllers(load_controller(out)).items():
        step = simulate_step(ctrl, models.motor(m), step_rad_s=10.0, duration_s=1.0,
                             extra_delay_ticks=3)  # fmt: skip
        banded = step_info(step.time_s, step.speed_rad_s, reference=10.0,
                           settling_band=QUANTUM / 10.0)  # fmt: skip
        tuned = rows[3]["motors"][m]
        assert tuned["overshoot_percent"] == pytest.approx(banded.overshoot_percent, abs=1e-9)
        assert tuned["settling_time_s"] == pytest.approx(banded.settling_time_s, abs=1e-9)
        assert tuned["max_abs_voltage"] == pytest.approx(step.peak_voltage_v, abs=1e-9)
        # three more ticks in the loop: slower, and never faster than the bound on that loop (60 ms)
        assert tuned["settling_time_s"] > rows[0]["motors"][m]["settling_time_s"] + 0.03
        assert tuned["settling_time_s"] >= 0.06
    assert rows[3]["settling_time_s"] > rows[0]["settling_time_s"]


def test_a_worker_runs_one_blas_thread() -> None:
    """The pool's initializer, checked with threadpoolctl's own view of the BLAS pools."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from cartctl.runtime.realtime import one_blas_thread

    # two threads first (the suite runs with one, conftest.py): the initializer must bring it down
    with threadpool_limits(limits=2, user_api="blas"):  # restores the pools afterwards
        assert {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"} == {2}
        one_blas_thread()
        blas = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    assert blas and set(blas) == {1}


@pytest.mark.parametrize(
    ("method", "new", "old", "keys"),
    [
        ("pi", "phase-margin=65,crossover-hz=3:4:1", "phase_margin=65,crossover_hz=3:4:1",
         ("phase-margin", "crossover-hz")),
        ("poles", "settling-time=0.06,overshoot=1", "settling_time=0.06,overshoot=1",
         ("settling-time", "overshoot")),
    ],
)  # fmt: skip
def test_the_grid_takes_designs_option_names_and_the_older_ones_alike(
    capsys: pytest.CaptureFixture[str], method: str, new: str, old: str, keys: tuple[str, str]
) -> None:
    """``--grid`` names an axis as design's option (``phase-margin`` for ``--phase-margin``) or,
    as before, with underscores: the same rows; ``--json`` keys the settings by the option."""
    rows = {spec: _tune_json(capsys, "--method", method, "--grid", spec, "--duration", "0.5")
            for spec in (new, old)}  # fmt: skip
    assert rows[new] == rows[old]
    assert all(tuple(r["settings"]) == keys for r in rows[new]["settings"])
    code = main(["tune", str(GROUND), "--method", method, "--grid", f"{old},{new}"])
    _, err = capsys.readouterr()
    assert code == 2 and f"--grid: axis '{keys[0]}' is given twice" in err
