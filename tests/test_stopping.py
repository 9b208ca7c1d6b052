"""Every way a run ends is a safe exit: real subprocesses, real signals.

``cartctl run`` in real time gets SIGINT, SIGTERM or SIGHUP once it records (on the model
simulator: both simulators are stepped plants, the stop is the loop's, and the model starts with
less CPU) and once while it starts (the physics simulator): it must send zero volts and log that
command as the trace's last row, close the CSV and the recording with as many rows as the summary
says, print the summary and exit 130, 143 or 129, with one line on stderr and no traceback. All wait on real processes in
real time (marked ``realtime``); what they wait for is the run's own progress (its stop handlers
installed, its first rows written), never a fixed time.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cartctl.data.read import read_trace

STARTED_TIMEOUT_S = 30.0

# A busy machine may make a real-time run skip a deadline: the trace then has a gap, which
# read_trace reports as a DataWarning. That is not what these tests are about.
pytestmark = [
    pytest.mark.realtime,
    pytest.mark.filterwarnings("ignore::cartctl.errors.DataWarning"),
]


def _start(workdir: Path, *argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "cartctl", *argv], cwd=workdir, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip


def _wait_recording(process: subprocess.Popen[str], csv: Path) -> None:
    """Until the run has written rows (the CSV has a data line), then a little more."""
    deadline = time.monotonic() + STARTED_TIMEOUT_S
    while time.monotonic() < deadline:
        if process.poll() is not None:
            pytest.fail(f"the run ended by itself: {process.communicate()}")
        if csv.exists() and csv.read_text(encoding="utf-8").count("\n") > 2:
            time.sleep(0.3)
            return
        time.sleep(0.05)
    pytest.fail("the run did not start recording")


def _caught_signals(pid: int) -> set[int]:
    """The signals process ``pid`` has handlers for (``SigCgt`` in ``/proc/PID/status``)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text(encoding="ascii")
    except OSError:  # gone
        return set()
    for line in status.splitlines():
        if line.startswith("SigCgt:"):
            mask = int(line.split()[1], 16)
            return {n for n in range(1, 65) if mask & (1 << (n - 1))}
    return set()


def _wait_stop_handlers(process: subprocess.Popen[str]) -> None:
    """Until cartctl's stop handlers are installed: SIGTERM and SIGHUP are caught (the interpreter
    catches SIGINT alone). The command's imports come after them."""
    deadline = time.monotonic() + STARTED_TIMEOUT_S
    while time.monotonic() < deadline:
        if process.poll() is not None:
            pytest.fail(f"the run ended by itself: {process.communicate()}")
        if {signal.SIGTERM, signal.SIGHUP} <= _caught_signals(process.pid):
            return
        time.sleep(0.001)
    pytest.fail("the run did not install its stop handlers")


def _check_stopped_run(workdir: Path, out: str, err: str, name: str, rrd_rows) -> None:
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("cartctl")]
    assert len(lines) == 1 and lines[0].startswith(f"cartctl run: stopped by SIG{name}"), err
    summary = json.loads(out)
    trace = read_trace(workdir / "logs" / "s.csv")
    assert summary["ticks"] == len(trace) > 10
    assert (trace.voltage_a[-1], trace.voltage_b[-1]) == (0.0, 0.0)  # the stop command, logged
    assert abs(trace.voltage_a[:-1]).max() > 0.0  # it was driving before
    rows = rrd_rows(workdir / "logs" / "s.rrd")  # needs the footer: closed properly
    assert rows["motor/a/voltage"] == rows["motor/b/speed"] == len(trace)


@pytest.mark.parametrize(
    ("signum", "code"),
    [(signal.SIGINT, 130), (signal.SIGHUP, 129)],  # SIGTERM: the next test's first signal
    ids=["SIGINT", "SIGHUP"],
)
def test_a_signal_mid_run_ends_it_safely(workdir: Path, signum: int, code: int, rrd_rows) -> None:
    process = _start(workdir, "run", "--plant", "sim", "--reference", "step:8",
                     "--duration", "30", "--rerun", "save", "--name", "s", "--json")  # fmt: skip
    _wait_recording(process, workdir / "logs" / "s.csv")
    process.send_signal(signum)
    out, err = process.communicate(timeout=30)
    assert process.returncode == code, err
    _check_stopped_run(workdir, out, err, signal.Signals(signum).name[3:], rrd_rows)


def test_a_second_signal_during_the_shutdown_does_not_cut_it_short(workdir: Path, rrd_rows) -> None:
    process = _start(workdir, "run", "--plant", "sim", "--reference", "step:8",
                     "--duration", "30", "--rerun", "save", "--name", "s", "--json")  # fmt: skip
    _wait_recording(process, workdir / "logs" / "s.csv")
    process.send_signal(signal.SIGTERM)
    time.sleep(0.005)
    process.send_signal(signal.SIGINT)
    time.sleep(0.005)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=30)
    assert process.returncode == 143, err  # the first signal decides
    _check_stopped_run(workdir, out, err, "TERM", rrd_rows)


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_while_starting_ends_with_one_line(workdir: Path, signum: int, code: int) -> None:
    process = _start(workdir, "run", "--plant", "physics", "--duration", "30", "--name", "s")
    _wait_stop_handlers(process)  # the interpreter is up, the command's imports are not done
    process.send_signal(signum)
    _, err = process.communicate(timeout=30)
    assert process.returncode == code, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert not (workdir / "logs" / "s.csv").exists() or read_trace(workdir / "logs" / "s.csv")


def test_monitor_stops_after_its_frame_on_sigterm(workdir: Path) -> None:
    """A monitor only listens: SIGTERM stops it as Ctrl-C does (files closed, summary), exit 143."""
    process = _start(workdir, "monitor", "virtual", "--rerun", "off", "--name", "m")
    csv = workdir / "logs" / "m.csv"
    _wait_recording(process, csv)
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=30)
    assert process.returncode == 143, err
    assert "Traceback" not in err and "frames" in out
    lines = csv.read_text(encoding="utf-8").splitlines()
    assert len(lines) > 10 and len({len(line.split(",")) for line in lines}) == 1  # whole rows


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 0), (signal.SIGTERM, 143)])
def test_the_virtual_cart_stops_on_a_signal_and_says_which(
    workdir: Path, signum: int, code: int
) -> None:
    """Ctrl-C is how a virtual cart is meant to stop (0, as monitor); SIGTERM and SIGHUP stop it as
    well, with their exit codes (it exited 0 on every signal)."""
    process = _start(workdir, "virtual-cart")
    assert process.stdout is not None
    port = process.stdout.readline().strip()  # printed once the cart is built: its handlers too
    assert port.startswith("/dev/"), port
    _wait_stop_handlers(process)
    process.send_signal(signum)
    _, err = process.communicate(timeout=30)
    assert process.returncode == code, err
    assert "Traceback" not in err, err
    # stopped before it booted (idle) or after; never "(running)": a cart left ticking
    assert "virtual cart stopped (stopped)" in err or "virtual cart stopped (idle)" in err, err
