"""The live status line: rewritten in place on a terminal, a few times a second of run time, from
the loop's idle time; nothing when stderr is not a terminal."""

from __future__ import annotations

import io
import json

import pytest

from cartctl.cli import main
from cartctl.sinks.base import TRACE_COLUMNS
from cartctl.sinks.summary import StatusLine


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _row(k: int, *, late_us: float = 0.0) -> tuple[float, ...]:
    values = {"time_s": k * 0.01, "voltage_a": 2.5, "voltage_b": -1.0, "speed_a": 9.75,
              "speed_b": 0.5, "tick": k, "reference_a": 10.0, "reference_b": 0.0,
              "estimate_a": 9.8, "estimate_b": 0.4, "period_error_us": late_us,
              "compute_us": 50.0}  # fmt: skip
    return tuple(values[c] for c in TRACE_COLUMNS)


def test_the_line_is_rewritten_every_quarter_second_of_run_time() -> None:
    term = Terminal()
    status = StatusLine(term, period_s=0.01)
    status.open(TRACE_COLUMNS)
    for k in range(100):  # one second of ticks, each followed by the loop's idle
        status.write(_row(k, late_us=20_000.0 if k == 30 else 0.0))
        status.idle()
    status.close()
    text = term.getvalue()
    assert text.count("\r") == 4 and text.endswith("\n")  # ticks 24, 49, 74, 99
    last = text.rsplit("\r", 1)[1]
    assert "t    0.99 s" in last and "tick     99" in last
    assert "a: r  10.00 y   9.75 rad/s u   2.50 V" in last
    assert "b: r   0.00 y   0.50 rad/s u  -1.00 V" in last
    assert "misses 1" in last  # tick 30 started 20 ms late


def test_write_alone_prints_nothing() -> None:
    term = Terminal()
    status = StatusLine(term, period_s=0.01)
    status.open(TRACE_COLUMNS)
    for k in range(100):
        status.write(_row(k))
    status.close()
    assert term.getvalue() == ""


@pytest.mark.realtime
def test_no_status_line_when_stderr_is_not_a_terminal(
    capsys: pytest.CaptureFixture[str], tmp_path
) -> None:
    code = main(["run", "--duration", "0.3", "--rerun", "off", "--out", str(tmp_path), "--json"])
    out, err = capsys.readouterr()
    assert code == 0 and json.loads(out)["ticks"] == 31
    assert "\r" not in err and "tick" not in err


@pytest.mark.realtime
def test_a_real_time_run_on_a_terminal_shows_the_line(tmp_path) -> None:
    import os
    import pty
    import subprocess
    import sys

    master, slave = pty.openpty()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "cartctl", "run", "--duration", "1", "--rerun", "off",
             "--out", str(tmp_path), "--json"],
            stdout=subprocess.PIPE, stderr=slave, timeout=60, check=False,
        )  # fmt: skip
        os.close(slave)
        slave = -1
        err = b""
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the terminal's other end is closed: all read
                break
            if not chunk:
                break
            err += chunk
    finally:
        if slave >= 0:
            os.close(slave)
        os.close(master)
    assert proc.returncode == 0, err.decode(errors="replace")
    assert json.loads(proc.stdout)["ticks"] == 101  # stdout stays the JSON alone
    lines = [part for part in err.decode().split("\r") if "tick" in part]  # the tty adds \r\n
    assert len(lines) == 4  # refreshed 4 times a second over 1 s (ticks 24, 49, 74, 99)
    assert "tick     99" in lines[-1] and "misses" in lines[-1]
