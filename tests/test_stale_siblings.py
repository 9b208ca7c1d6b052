"""A trace written over an earlier run's name leaves none of that run's files beside it: its
recording (``X.rrd``) or meta file (``X.meta.toml``) would pass for the new trace's
(``review X.rrd`` showed the old run; ``identify X.csv`` took its loop delay)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from cartctl.cli import main

EXCITE = ["excite", "--amplitude", "5", "--cycles", "1"]


def _ok(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    code = main(argv)
    assert code == 0, capsys.readouterr().err
    capsys.readouterr()


def test_excite_removes_an_earlier_runs_recording(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("x.rrd").write_bytes(b"an earlier run's recording")
    _ok(capsys, [*EXCITE, "--out", "x.csv"])
    assert sorted(os.listdir()) == ["x.csv", "x.meta.toml"]
    _ok(capsys, [*EXCITE, "--out", "z.rrd"])  # a trace named so is not removed as a recording
    assert Path("z.rrd").read_text(encoding="utf-8").startswith("time_s,")


def test_convert_removes_an_earlier_runs_recording(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)
    _ok(capsys, [*EXCITE, "--out", "x.csv"])
    Path("y.rrd").write_bytes(b"an earlier run's recording")
    _ok(capsys, ["convert", "x.csv", "--out", "y.csv"])
    assert not Path("y.rrd").exists()
    Path("x.rrd").write_bytes(b"the trace's own recording")  # converted onto itself: kept
    _ok(capsys, ["convert", "x.csv", "--out", "./x.csv"])
    assert Path("x.rrd").read_bytes() == b"the trace's own recording"
