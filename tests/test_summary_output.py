"""One duration for one trace, a virtual clock's timing said as such, and compute's maximum in
``review --json``: ``run`` and ``review`` through the CLI on the same trace."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data import read_trace


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


def test_a_virtual_clock_prints_no_timing_figures(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    _, out = _cli(capsys, "run", "--fast", "--duration", "2", "--out", str(tmp_path), "--name",
                  "t", "--rerun", "off")  # fmt: skip
    first = out.splitlines()[0]
    assert first.startswith("201 ticks, 2.00 s;")
    assert "virtual clock, no real-time figures" in first and "compute" not in first
    _, out = _cli(capsys, "review", str(tmp_path / "t.csv"))
    assert out.splitlines()[0] == first  # the same line for the same trace
