"""One duration for one trace, a simulated clock's timing said as such, and compute's maximum in
``review --json``: ``run`` and ``review`` through the CLI on the same trace. Units in every
column header of the summary, one rounding per column (three significant figures of its largest
value, checked against the exact ``--json`` figures), a numerical zero printed as 0, and
``--json`` on every command that prints results."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.read import read_trace


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert code == 0, err
    return code, out


def test_run_and_review_report_one_duration(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    _, out = _cli(capsys, "run", "--fast", "--duration", "5", "--out", str(tmp_path), "--name",
                  "t", "--rerun", "off", "--json")  # fmt: skip
    ran = json.loads(out)
    _, out = _cli(capsys, "review", str(tmp_path / "t.csv"), "--json")
    reviewed = json.loads(out)
    trace = read_trace(tmp_path / "t.csv")
    span = trace.time_s[-1] - trace.time_s[0]  # 500 ticks and the stop row at 5.00 s
    assert span == pytest.approx(5.0)
    assert ran["duration_s"] == reviewed["duration_s"] == pytest.approx(span)
    assert ran["ticks"] == reviewed["ticks"] == len(trace) == 501
    assert reviewed["compute_us"]["max"] == np.max(trace.column("compute_us"))


def test_a_simulated_clock_prints_no_timing_figures(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    _, out = _cli(capsys, "run", "--fast", "--duration", "2", "--out", str(tmp_path), "--name",
                  "t", "--rerun", "off")  # fmt: skip
    first = out.splitlines()[0]
    assert first.startswith("201 ticks, 2.00 s;")
    assert "simulated clock, no real-time figures" in first and "compute" not in first
    _, out = _cli(capsys, "review", str(tmp_path / "t.csv"))
    assert out.splitlines()[0] == first  # the same line for the same trace


# -- units and rounding (issue 15, item 6) -------------------------------------------------------

SUMMARY_KEYS = {"overshoot (%)": ("overshoot_percent", 1.0), "rise (ms)": ("rise_time_s", 1e3),
                "settling (ms)": ("settling_time_s", 1e3),
                "ss error (rad/s)": ("steady_state_error", 1.0),
                "rms error (rad/s)": ("rms_error", 1.0),
                "max |V| (V)": ("max_abs_voltage", 1.0)}  # fmt: skip


def _significant(cell: str) -> int:
    """Significant digits of a printed number (leading zeros never count, nor an integer's
    trailing zeros: 1230 has three)."""
    digits = cell.lstrip("-")
    if "." not in digits:
        digits = digits.rstrip("0") or "0"
    return len(digits.replace(".", "").lstrip("0"))


def _motor_table(out: str) -> tuple[list[str], dict[str, dict[str, str]]]:
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("  motor  "))
    headers = re.split(r"\s{2,}", lines[head].strip())
    rows = {}
    for line in lines[head + 1 : head + 3]:
        cells = re.split(r"\s{2,}", line.strip())
        assert len(cells) == len(headers), line
        rows[cells[0]] = dict(zip(headers, cells, strict=True))
    return headers, rows


def _check_table(out: str, motors: dict) -> dict[str, dict[str, str]]:
    """Every header has a unit; per column one number of decimals, at most 3 significant
    figures, each cell the exact value rounded; the two errors (rad/s) share their rounding."""
    headers, rows = _motor_table(out)
    assert headers[0] == "motor" and set(headers[1:]) == set(SUMMARY_KEYS)
    assert all(re.search(r" \((%|ms|rad/s|V)\)$", h) for h in headers[1:]), headers
    decimals_of = {}
    for head, (key, factor) in SUMMARY_KEYS.items():
        cells = [(rows[m][head], motors[m][key]) for m in rows if motors[m][key] is not None]
        assert all(re.fullmatch(r"-?\d+(\.\d+)?", c) for c, _ in cells), cells  # no 3.6e-15
        decimals = {len(c.partition(".")[2]) for c, _ in cells}
        assert len(decimals) == 1, (head, cells)
        decimals_of[head] = decimals.pop()
        assert max(_significant(c) for c, _ in cells) <= 3, (head, cells)
        for cell, exact in cells:
            assert abs(float(cell) - exact * factor) <= 0.5 * 10.0 ** -decimals_of[head] + 1e-12
            assert not (cell.startswith("-") and float(cell) == 0.0)
    assert decimals_of["ss error (rad/s)"] == decimals_of["rms error (rad/s)"]
    return rows


def test_summary_columns_have_units_and_one_rounding_and_a_numerical_zero_prints_as_0(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    _, out = _cli(capsys, "run", "--fast", "--duration", "2", "--out", str(tmp_path), "--name",
                  "t", "--rerun", "off")  # fmt: skip
    _, doc = _cli(capsys, "review", str(tmp_path / "t.csv"), "--json")
    motors = json.loads(doc)["motors"]
    # on the model the PI's integrator removes the error to rounding level
    assert all(abs(motors[m]["steady_state_error"]) < 1e-9 for m in "ab")
    rows = _check_table(out, motors)
    for m in "ab":  # a zero with the RMS error's decimals (checked above), no sign, no exponent
        assert (
            float(rows[m]["ss error (rad/s)"]) == 0.0 and float(rows[m]["rms error (rad/s)"]) > 0.5
        )
    _, reviewed = _cli(capsys, "review", str(tmp_path / "t.csv"))
    assert _motor_table(reviewed) == _motor_table(out)  # review prints the same table


def test_a_negative_steady_state_error_keeps_its_sign_and_the_errors_rounding(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """Pole placement on the physics preset leaves a few mrad/s of error, of both signs (a 5 rad/s
    step; negative with the command landing 10 ms after its tick)."""
    _, out = _cli(capsys, "run", "--fast", "--plant", "physics:actuation_ms=10", "--controller",
                  "controllers/poles.toml", "--reference", "step:5", "--duration", "2", "--out",
                  str(tmp_path), "--name",
                  "p", "--rerun", "off")  # fmt: skip
    _, doc = _cli(capsys, "review", str(tmp_path / "p.csv"), "--json")
    motors = json.loads(doc)["motors"]
    rows = _check_table(out, motors)
    assert any(motors[m]["steady_state_error"] < -0.0005 for m in "ab")  # a negative one shown
    for m in "ab":
        exact = motors[m]["steady_state_error"]
        if abs(exact) >= 0.0005:  # shown at the RMS error's 3 decimals
            assert rows[m]["ss error (rad/s)"].startswith("-") == (exact < 0)


def test_timing_figures_have_three_significant_figures(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A trace with real-time-like timing columns: review's timing line, each triple rounded
    to three significant figures of its largest value."""
    _cli(capsys, "run", "--fast", "--duration", "1", "--out", str(tmp_path), "--name", "t",
         "--rerun", "off")  # fmt: skip
    with (tmp_path / "t.csv").open(newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    pe, cu = head.index("period_error_us"), head.index("compute_us")
    rng = np.random.default_rng(3)
    for row in rows[1:]:
        row[pe] = repr(float(rng.uniform(0.5, 40.0)))
        row[cu] = repr(float(rng.uniform(90.0, 180.0)))
    rows[5][cu] = "1234.5678"  # one slow tick
    with (tmp_path / "timed.csv").open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    _, out = _cli(capsys, "review", str(tmp_path / "timed.csv"))
    first = out.splitlines()[0]
    found = re.search(r"period error p50/p99/max (\S+) µs; compute p50/p99/max (\S+) µs", first)
    assert found, first
    trace = read_trace(tmp_path / "timed.csv")
    for text, column in zip(found.groups(), ("period_error_us", "compute_us"), strict=True):
        values = trace.column(column)
        exact = [np.percentile(values, 50), np.percentile(values, 99), np.max(values)]
        cells = text.split("/")
        assert max(_significant(c) for c in cells) <= 3 and len(cells) == 3
        top = max(exact)
        unit = 10.0 ** (np.floor(np.log10(top)) - 2)  # the last of three figures of the largest
        for cell, value in zip(cells, exact, strict=True):
            assert abs(float(cell) - value) <= unit / 2 + 1e-9, (cell, value)
    assert found.group(2).endswith("/1230")


@pytest.mark.parametrize(
    "command",
    ["excite", "identify", "inspect", "validate", "linearity", "design", "run", "review", "tune",
     "convert", "monitor"],
)  # fmt: skip
def test_every_command_that_prints_results_has_json(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as done:
        main([command, "--help"])
    assert done.value.code == 0
    assert re.search(r"^\s+--json\b", capsys.readouterr().out, re.MULTILINE)
