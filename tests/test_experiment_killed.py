"""An experiment killed outright (SIGKILL, a segfault, a power loss: no handler runs) keeps the rows
recorded so far: ``excite`` and ``commission`` stream their traces through the CSV sink ``run``
uses, and write the meta file with the first row. Both kept the whole trace in memory and wrote it
at the end, so a kill lost the experiment. The process kills itself from inside a plant's step at
a fixed tick (no timing): blocks of 1000 rows on a simulated plant, so 2000 rows are on disk."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.read import read_trace
from cartctl.data.trace import read_trace_meta
from cartctl.plants.base import ClockedPlant, Measurement
from cartctl.runtime.loop import run_experiment
from cartctl.sinks.csv_sink import CsvSink

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


class _Cart:
    """A cart-clocked plant (no true speeds) noting the trace file's size at each send and
    receive."""

    period_s, arrival_s, tick_index = 0.01, 0.0, 0

    def __init__(self, path: Path) -> None:
        self.path, self.sizes = path, []

    def _size(self, what: str) -> None:
        self.sizes.append((what, self.path.stat().st_size if self.path.exists() else 0))

    def connect(self) -> None:
        pass

    def reset(self) -> Measurement:
        self.tick_index = 0
        return Measurement(0.0, 0.0)

    def send(self, voltage_a_v: float, voltage_b_v: float) -> None:
        self._size("send")

    def receive(self) -> Measurement:
        self._size("receive")
        self.tick_index += 1
        return Measurement(float(self.tick_index), 0.0)

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        self.send(voltage_a_v, voltage_b_v)
        return self.receive()

    def close(self) -> None:
        pass


def test_a_cart_experiment_writes_its_blocks_between_a_command_and_the_next_tick(
    tmp_path: Path,
) -> None:
    """As ``run``'s loop does on a cart: a block of 50 rows is written after the tick's command
    went out, while the cart's next tick is awaited, never between a measurement and its answer."""
    path = tmp_path / "cart.csv"
    cart = _Cart(path)
    assert isinstance(cart, ClockedPlant)
    result = run_experiment(cart, np.ones(120), np.zeros(120), sink=CsvSink(path, flush_every=50))
    grew = [k for k in range(1, len(cart.sizes)) if cart.sizes[k][1] > cart.sizes[k - 1][1]]
    assert [cart.sizes[k][0] for k in grew] == ["receive", "receive"]  # rows 50 and 100
    assert len(grew) == 2 and read_trace(path).speed_a.tolist() == result.trace.speed_a.tolist()
    assert path.read_text().splitlines()[0] == "time_s,voltage_a,voltage_b,speed_a,speed_b"


def test_a_stop_signal_while_a_cart_experiments_block_is_written_keeps_the_block(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, stop_handlers: None
) -> None:
    """Ctrl-C while a block of 50 rows goes to the file (after the command, before the next
    tick): the block is written whole, then the experiment stops; it was taken from the sink and
    lost (the file held the header only while the result, and excite's line, had 50 rows)."""
    original, calls = CsvSink._take_text, []

    def take_text(self: CsvSink) -> bytes:
        data = original(self)
        calls.append(len(data))
        if len(calls) == 2:  # the header, then the first block
            os.kill(os.getpid(), signal.SIGINT)
        return data

    monkeypatch.setattr(CsvSink, "_take_text", take_text)
    path = tmp_path / "cart.csv"
    result = run_experiment(
        _Cart(path), np.ones(120), np.zeros(120), sink=CsvSink(path, flush_every=50)
    )
    assert result.interrupted and len(result.trace) == 50
    assert read_trace(path).speed_a.tolist() == result.trace.speed_a.tolist()
