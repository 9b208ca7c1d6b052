"""A stop signal at the moments around a command's loop or experiment: before the loop owns the
plant, after the last tick, while the trace is written. Each test sends the signal to this process
from inside the command's own code at that moment (a wrapped function), with cartctl's real
handlers (``cli.main`` installs them).

Found by stopping commands at random moments (SIGINT, SIGTERM, SIGHUP, single and in bursts):
``run --fast`` stopped after its last tick printed no summary, only 'cartctl run: interrupted',
over a whole trace; a signal between ``run``'s preparation and its loop left the plant open (a
virtual cart's threads ticking on).
"""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from cartctl.cli import main
from cartctl.cli.commands import run as run_command
from cartctl.data.read import read_trace


def _signalling(call: Callable[..., Any], signum: int = signal.SIGTERM) -> Callable[..., Any]:
    """``call``, after sending ``signum`` to this process (the handler raises at once)."""

    def wrapped(*args: Any, **kwargs: Any) -> Any:
        os.kill(os.getpid(), signum)
        return call(*args, **kwargs)

    return wrapped


def _lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.strip()]


def test_run_a_signal_after_the_last_tick_still_prints_the_summary(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import cartctl.sinks.summary as summary_module

    monkeypatch.setattr(summary_module, "trace_metrics", _signalling(summary_module.trace_metrics))
    code = main(["run", "--fast", "--duration", "1", "--rerun", "off", "--name", "s", "--json"])
    out, err = capsys.readouterr()
    assert code == 143
    assert _lines(err) == ["cartctl run: stopped by SIGTERM; zero volts sent, the trace and "
                           "recording hold the run so far"]  # fmt: skip
    summary = json.loads(out)
    trace = read_trace(workdir / "logs" / "s.csv")
    assert summary["ticks"] == len(trace) == 101  # every tick and the stop row
    assert (trace.voltage_a[-1], trace.voltage_b[-1]) == (0.0, 0.0)


def test_run_a_signal_before_the_loop_closes_the_plant(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    closed: list[bool] = []
    original = run_command.make_plant

    def make_plant(*args: Any, **kwargs: Any) -> Any:
        plant, description = original(*args, **kwargs)
        close = plant.close
        plant.close = lambda: (closed.append(True), close())[1]
        return plant, description

    monkeypatch.setattr(run_command, "make_plant", make_plant)
    monkeypatch.setattr(run_command, "_sinks", _signalling(run_command._sinks))
    code = main(["run", "--fast", "--duration", "1", "--rerun", "off", "--name", "s"])
    err = capsys.readouterr().err
    assert code == 143
    assert len(_lines(err)) == 1 and "Traceback" not in err
    assert closed == [True]
    assert not (workdir / "logs" / "s.csv").exists()  # nothing driven, no trace
