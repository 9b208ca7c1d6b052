"""An experiment killed outright (SIGKILL, a segfault, a power loss: no handler runs) keeps the rows
recorded so far: ``excite`` and ``commission`` stream their traces through the CSV sink ``run``
uses, and write the meta file with the first row. Both kept the whole trace in memory and wrote it
at the end, so a kill lost the experiment. The process kills itself from inside a plant's step at
a fixed tick (no timing): blocks of 1000 rows on a simulated plant, so 2000 rows are on disk."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cartctl.cli import main
from cartctl.data.read import read_trace
from cartctl.data.trace import read_trace_meta

ROOT = Path(__file__).resolve().parents[1]

KILLER = """
import os, signal, sys
from cartctl.plants.{module} import {plant} as Plant
from cartctl.cli import main

step, reset, done = Plant.step, Plant.reset, [0]

def resetting(self, *args, **kwargs):  # each experiment counts its own steps
    done[0] = 0
    return reset(self, *args, **kwargs)

def stepping(self, ua, ub):
    done[0] += 1
    if done[0] == {kill_at}:  # rows 0..{kill_at}-1 recorded, in blocks of 1000 on disk
        os.kill(os.getpid(), signal.SIGKILL)
    return step(self, ua, ub)

Plant.reset, Plant.step = resetting, stepping
sys.exit(main(sys.argv[1:]))
"""


def _killed(module: str, plant: str, kill_at: int, *argv: str) -> subprocess.CompletedProcess[str]:
    script = KILLER.format(module=module, plant=plant, kill_at=kill_at)
    return subprocess.run([sys.executable, "-c", script, *argv], cwd=ROOT, text=True,
                          capture_output=True, timeout=300, check=False)  # fmt: skip


def test_excite_killed_mid_experiment_leaves_a_trace_identify_reads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ex.csv"
    argv = ["excite", "--plant", "sim", "--signal", "prbs", "--amplitude", "5", "--duration", "60"]
    result = _killed("sim", "ArxPlant", 2501, *argv, "--out", str(out))
    assert result.returncode == -signal.SIGKILL, result.stderr
    trace = read_trace(out)
    assert len(trace) == 2000  # the whole blocks written before the kill
    assert list(trace.columns())[:5] == ["time_s", "voltage_a", "voltage_b", "speed_a", "speed_b"]
    meta = read_trace_meta(out)
    assert meta is not None and meta.loop_delay_ticks == 1 and meta.plant.startswith("sim")
    capsys.readouterr()
    assert main(["identify", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)


def test_commission_killed_mid_excitation_keeps_the_rows_so_far(tmp_path: Path) -> None:
    out = tmp_path / "c"
    result = _killed("physics", "PhysicsPlant", 1201, "commission", "physics", "--out", str(out))
    assert result.returncode == -signal.SIGKILL, result.stderr
    assert len(read_trace(out / "checks.csv")) == 540  # the checks, done before
    assert len(read_trace(out / "excitation.csv")) == 1000  # killed at its 1201st tick of 1500
    meta = read_trace_meta(out / "excitation.csv")
    assert meta is not None and meta.loop_delay_ticks == 1
