"""``cartctl review A.csv --compare B.csv``: one table of A, B, B − A and (B − A)/|A|, and --json.

Two short ``run --fast`` traces (the shipped PI and pole-placement controllers); the expected
differences are computed here from the two single ``review --json`` outputs.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from cartctl.cli import main

ROOT = Path(__file__).resolve().parents[1]
MOTOR_KEYS = ("overshoot_percent", "settling_time_s", "rise_time_s", "steady_state_error",
              "rms_error", "max_abs_voltage")  # fmt: skip


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def two_runs(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> tuple[Path, Path]:
    paths = []
    for name in ("pi", "poles"):
        code, _, err = _cli(capsys, "run", "--fast", "--duration", "1.5", "--model",
                            str(ROOT / "models" / "ground.toml"), "--controller",
                            str(ROOT / "controllers" / f"{name}.toml"), "--rerun", "off",
                            "--out", str(tmp_path), "--name", name)  # fmt: skip
        assert code == 0, err
        paths.append(tmp_path / f"{name}.csv")
    return paths[0], paths[1]


def _single(capsys: pytest.CaptureFixture[str], path: Path) -> dict:
    code, out, err = _cli(capsys, "review", str(path), "--json")
    assert code == 0, err
    return json.loads(out)


def test_compare_json_is_b_minus_a(
    two_runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    a_path, b_path = two_runs
    a, b = _single(capsys, a_path), _single(capsys, b_path)
    code, out, err = _cli(capsys, "review", str(a_path), "--compare", str(b_path), "--json")
    assert code == 0, err
    both = json.loads(out)
    assert both["runs"] == [a, b]  # the key that was there before
    assert both["a"] == a and both["b"] == b
    diff, percent = both["difference"], both["difference_percent"]
    for m in ("a", "b"):
        for key in MOTOR_KEYS:
            x, y = a["motors"][m][key], b["motors"][m][key]
            assert diff["motors"][m][key] == pytest.approx(y - x, rel=1e-12, abs=1e-15)
        x, y = a["motors"][m]["rms_error"], b["motors"][m]["rms_error"]
        assert percent["motors"][m]["rms_error"] == pytest.approx((y - x) / abs(x) * 100)
        assert "overshoot_percent" not in percent["motors"][m]  # a ratio of percentages: none
    assert diff["ticks"] == b["ticks"] - a["ticks"] == 0
    assert diff["duration_s"] == pytest.approx(b["duration_s"] - a["duration_s"])
    assert diff["compute_us"]["max"] == b["compute_us"]["max"] - a["compute_us"]["max"]
    assert "trace" not in diff and "metrics_signal" not in diff  # no numbers, no difference
    # the two controllers differ: pole placement rises faster on this model
    assert diff["motors"]["a"]["rise_time_s"] < 0


def test_compare_table_in_the_terminal(
    two_runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    a_path, b_path = two_runs
    a, b = _single(capsys, a_path), _single(capsys, b_path)
    code, out, err = _cli(capsys, "review", str(a_path), "--compare", str(b_path))
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0] == f"A: {a_path}" and lines[1] == f"B: {b_path}"
    head = next(line for line in lines if line.strip().startswith("metric"))
    assert re.search(r"A\s+B\s+B − A\s+\(B − A\)/\|A\|", head)
    rows = {}
    for line in lines[lines.index(head) + 1 :]:
        label, *cells = re.split(r"\s{2,}", line.strip())
        rows[label] = cells
    assert len(rows) == 3 + 2 * len(MOTOR_KEYS)  # ticks, duration, misses; 6 per motor
    for m in ("a", "b"):
        ra, rb = a["motors"][m]["rise_time_s"] * 1e3, b["motors"][m]["rise_time_s"] * 1e3
        cells = rows[f"motor {m}: rise time 10–90 % (ms)"]
        assert cells[:2] == [f"{ra:.1f}", f"{rb:.1f}"]
        assert float(cells[2]) == pytest.approx(rb - ra, abs=0.05)
        assert cells[3] == f"{(rb - ra) / ra * 100:+.1f} %"
        va, vb = a["motors"][m]["max_abs_voltage"], b["motors"][m]["max_abs_voltage"]
        assert rows[f"motor {m}: max |voltage| (V)"][:2] == [f"{va:.2f}", f"{vb:.2f}"]
        assert rows[f"motor {m}: overshoot (%)"][3] == "—"
    assert "simulated clock" in out  # --fast runs: no timing rows of zeros
    assert not any("compute" in label for label in rows)


def test_compare_refuses_a_recording(
    two_runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, out, err = _cli(capsys, "review", str(two_runs[0]), "--compare", str(tmp_path / "x.rrd"))
    assert code == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert "--compare takes a second CSV trace" in line


def test_compare_shows_the_smoothed_metrics(
    two_runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """With --model (or a trace without a true speed) each run has smoothed metrics: the table
    shows them beside the others (it dropped them, so --model changed nothing in it)."""
    a_path, b_path = two_runs
    model = str(ROOT / "models" / "ground.toml")
    single = []
    for path in (a_path, b_path):
        code, out, err = _cli(capsys, "review", str(path), "--model", model, "--json")
        assert code == 0, err
        single.append(json.loads(out)["motors"])
    code, out, err = _cli(capsys, "review", str(a_path), "--compare", str(b_path), "--model", model)
    assert code == 0, err
    rows = {}
    for line in out.splitlines():
        label, *cells = re.split(r"\s{2,}", line.strip())
        rows[label] = cells
    for m in ("a", "b"):
        ra, rb = (s[m]["smoothed"]["rise_time_s"] * 1e3 for s in single)
        assert rows[f"motor {m} smoothed: rise time 10–90 % (ms)"][:2] == [f"{ra:.1f}", f"{rb:.1f}"]
        assert f"motor {m}: rise time 10–90 % (ms)" in rows  # the true speed's, as before
    argv = ["review", str(a_path), "--compare", str(b_path), "--model", model, "--json"]
    code, out, err = _cli(capsys, *argv)
    assert code == 0, err
    ea, eb = (s["a"]["smoothed"]["rms_error"] for s in single)
    smoothed = json.loads(out)["difference_percent"]["motors"]["a"]["smoothed"]
    assert smoothed["rms_error"] == pytest.approx((eb - ea) / abs(ea) * 100)


def test_compare_says_when_the_runs_are_judged_on_different_speeds(
    two_runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A simulator's run is judged on its true speed, a cart's on the measured one: the table
    says so when A and B differ (it set the two side by side without a word)."""
    import csv

    a_path, b_path = two_runs
    with b_path.open(newline="") as f:
        rows = list(csv.reader(f))
    keep = [i for i, name in enumerate(rows[0]) if not name.startswith("true_speed")]
    cart = tmp_path / "cart.csv"  # B as a real cart's trace: no true speed
    with cart.open("w", newline="") as f:
        csv.writer(f).writerows([[row[i] for i in keep] for row in rows])
    code, out, err = _cli(capsys, "review", str(a_path), "--compare", str(cart))
    assert code == 0, err
    assert "  tracking on the true speed in A, on the measured speed in B" in out.splitlines()
    code, out, err = _cli(capsys, "review", str(a_path), "--compare", str(b_path))
    assert code == 0 and "tracking on" not in out


def test_compare_takes_map_to_the_trace_whose_columns_it_names(
    two_runs: tuple[Path, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """An own run beside a foreign log (QRC's default labels): --map goes to the trace holding
    the columns it names, in either order (it went to both, and the own run lacked them)."""
    a_path, b_path = two_runs
    labels = {"speed_a": "FloatIn0", "speed_b": "FloatIn1", "voltage_a": "FloatIn2",
              "voltage_b": "FloatIn3", "reference_a": "FloatIn4", "reference_b": "FloatIn5"}  # fmt: skip
    lines = b_path.read_text().splitlines(keepends=True)
    foreign = tmp_path / "foreign.csv"
    foreign.write_text(",".join(labels.get(n, n) for n in lines[0].strip().split(",")) + "\n"
                       + "".join(lines[1:]))  # fmt: skip
    mapping = ",".join(f"{n}={label}" for n, label in labels.items())
    a, b = _single(capsys, a_path), _single(capsys, b_path)
    for first, second in ((a_path, foreign), (foreign, a_path)):
        argv = ["review", str(first), "--compare", str(second), "--map", mapping, "--json"]
        code, out, err = _cli(capsys, *argv)
        assert code == 0, err
        runs = [{k: v for k, v in run.items() if k != "trace"} for run in json.loads(out)["runs"]]
        expected = [{k: v for k, v in run.items() if k != "trace"} for run in (a, b)]
        assert runs == (expected if first == a_path else expected[::-1])
    code, out, err = _cli(capsys, "review", str(a_path), "--compare", str(b_path), "--map", mapping)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1  # neither has them
    assert "FloatIn" in err
