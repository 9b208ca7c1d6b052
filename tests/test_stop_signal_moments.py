"""A stop signal at the moments around a command's loop or experiment: before the loop owns the
plant, after the last tick, while the trace is written. Each test sends the signal to this process
from inside the command's own code at that moment (a wrapped function), with cartctl's real
handlers (``cli.main`` installs them).

Found by stopping commands at random moments (SIGINT, SIGTERM, SIGHUP, single and in bursts):
``run --fast`` stopped after its last tick printed no summary, only 'cartctl run: interrupted',
over a whole trace; ``excite`` stopped while writing its trace left a cut trace (626 of 18000
ticks), no meta file and no word of it; a signal between ``run``'s preparation and its loop left
the plant open (a virtual cart's threads ticking on).
"""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from cartctl.cli import main
from cartctl.cli.commands import run as run_command
from cartctl.data.read import read_trace
from cartctl.data.trace import meta_path


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
    monkeypatch.setattr(run_command, "_summary", _signalling(run_command._summary))
    code = main(["run", "--fast", "--duration", "1", "--rerun", "off", "--name", "s", "--json"])
    out, err = capsys.readouterr()
    assert code == 143
    assert _lines(err) == ["cartctl run: stopped by SIGTERM; zero volts sent, the trace and "
                           "recording hold the run so far"]  # fmt: skip
    summary = json.loads(out)
    trace = read_trace(workdir / "logs" / "s.csv")
    assert summary["ticks"] == len(trace) == 101  # every tick and the stop row
    assert (trace.voltage_a[-1], trace.voltage_b[-1]) == (0.0, 0.0)


def test_run_a_signal_during_a_completed_runs_shutdown_is_not_swallowed(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from cartctl.runtime.loop import ControlLoop

    monkeypatch.setattr(ControlLoop, "finish", _signalling(ControlLoop.finish))
    code = main(["run", "--fast", "--duration", "1", "--rerun", "off", "--name", "s", "--json"])
    out, err = capsys.readouterr()
    assert code == 143  # was 0: the signal noted during the shutdown, then forgotten
    assert len(_lines(err)) == 1 and "stopped by SIGTERM" in err
    assert json.loads(out)["ticks"] == len(read_trace(workdir / "logs" / "s.csv")) == 101


def test_run_a_signal_before_the_loop_closes_the_plant(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from cartctl.plants import factory

    closed: list[bool] = []
    original = factory.make_plant

    def make_plant(*args: Any, **kwargs: Any) -> Any:
        plant, description = original(*args, **kwargs)
        close = plant.close
        plant.close = lambda: (closed.append(True), close())[1]
        return plant, description

    monkeypatch.setattr(factory, "make_plant", make_plant)
    monkeypatch.setattr(run_command, "_sinks", _signalling(run_command._sinks))
    code = main(["run", "--fast", "--duration", "1", "--rerun", "off", "--name", "s"])
    err = capsys.readouterr().err
    assert code == 143
    assert len(_lines(err)) == 1 and "Traceback" not in err
    assert closed == [True]
    assert not (workdir / "logs" / "s.csv").exists()  # nothing driven, no trace


def test_run_a_signal_before_the_sinks_open_is_one_line(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """As the loop starts (a real-time run locks its memory and collects first): the summary of no
    rows was an error, 'the trace has no 'time_s' column', and exit 2."""
    from cartctl.runtime.loop import ControlLoop

    monkeypatch.setattr(ControlLoop, "start", _signalling(ControlLoop.start))
    code = main(["run", "--fast", "--duration", "1", "--rerun", "off", "--name", "s", "--json"])
    out, err = capsys.readouterr()
    assert code == 143
    assert _lines(err) == ["cartctl run: stopped by SIGTERM before the first tick; zero volts "
                           "sent, nothing recorded"]  # fmt: skip
    assert out == ""
    assert not (workdir / "logs" / "s.csv").exists()


def test_excite_a_signal_while_the_trace_is_written_leaves_it_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The trace goes to the file as it is recorded (blocks of 1000 rows on a simulated plant): a
    signal while a block is written stops the experiment with every row so far in the file."""
    from cartctl.sinks.csv_sink import CsvSink

    original, blocks = CsvSink._flush, []

    def flush(self: CsvSink) -> None:
        original(self)
        blocks.append(self.rows_written)
        if len(blocks) == 2:  # the header, then the first 1000 rows
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(CsvSink, "_flush", flush)
    out = tmp_path / "x.csv"
    code = main(["excite", "--plant", "physics", "--amplitude", "10", "--cycles", "5",
                 "--out", str(out), "--json"])  # fmt: skip
    stdout, err = capsys.readouterr()
    assert code == 130
    assert len(_lines(err)) == 1 and "Traceback" not in err
    assert len(read_trace(out)) == json.loads(stdout)["ticks"] == 1000 == blocks[1]
    assert meta_path(out).is_file()


def test_commission_a_signal_while_a_stage_trace_is_written_leaves_it_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from cartctl.sinks.csv_sink import CsvSink

    closed: list[Path] = []

    def close(self: CsvSink) -> None:
        os.kill(os.getpid(), signal.SIGTERM)  # the checks' experiment is over: its last rows
        original(self)
        closed.append(self.path)

    original = CsvSink.close
    monkeypatch.setattr(CsvSink, "close", close)
    out = tmp_path / "c"
    code = main(["commission", "physics", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 143
    assert "Traceback" not in err
    assert closed == [out / "checks.csv"]
    assert len(read_trace(out / "checks.csv")) == 540  # the whole checks sequence
    assert meta_path(out / "checks.csv").is_file()
    assert "checks: interrupted; zero volts sent" in _lines(err)[-1]


class _Thing:
    """An object to hang a weakref callback on."""


def test_a_signal_inside_a_weakref_callback_is_raised_in_the_code_around(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Python cannot raise an exception out of a weakref callback: it prints 'Exception ignored in'
    with a traceback and goes on. The stop signal is sent again, and raised where it can be."""
    import weakref

    from cartctl import stopping

    previous = stopping.install()
    try:

        def drop_then_wait() -> None:
            thing = _Thing()
            ref = weakref.ref(thing, lambda _: os.kill(os.getpid(), signal.SIGHUP))
            del thing  # the callback runs here, and the handler raises inside it
            assert ref() is None
            stopping._redelivered.acquire()  # type: ignore[attr-defined]
            stopping.received()  # any call: the signal sent again is raised by now

        with pytest.raises(stopping.Interrupted) as raised:
            drop_then_wait()
        assert raised.value.signum == signal.SIGHUP
        assert stopping.received() == signal.SIGHUP
    finally:
        stopping.restore(previous)
    assert "Exception ignored" not in capsys.readouterr().err


def test_commission_a_signal_lost_in_a_weakref_callback_still_stops_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """As a figure of the checks is drawn (matplotlib's weakref callbacks): the signal was lost,
    and with it every later one; the excitation and the rest ran on, and exit 0."""
    import weakref

    from cartctl.commission import report

    def plot_lines(*args: Any, **kwargs: Any) -> None:
        thing = _Thing()
        ref = weakref.ref(thing, lambda _: os.kill(os.getpid(), signal.SIGINT))
        del thing
        assert ref() is None
        original(*args, **kwargs)

    original = report.plot_lines
    monkeypatch.setattr(report, "plot_lines", plot_lines)
    out = tmp_path / "c"
    code = main(["commission", "physics", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 130
    assert "Exception ignored" not in err and "Traceback" not in err
    assert "interrupted; zero volts sent" in _lines(err)[-1]
    assert not (out / "controller.toml").exists()


def _burst_while_blocked(*signums: int) -> None:
    """Send ``signums`` one after the other from another thread, while this one waits in a lock
    (no bytecode): Python then runs their handlers together, in the order of their numbers."""
    import _thread

    done = _thread.allocate_lock()
    done.acquire()

    def burst() -> None:
        for signum in signums:
            signal.raise_signal(signum)
        done.release()

    _thread.start_new_thread(burst, ())
    done.acquire()  # the handlers run as this returns


def test_the_first_signal_counts_when_python_runs_the_handlers_of_a_burst_together() -> None:
    """``tune --jobs 2`` (its pool's thread holding the interpreter) or ``identify`` (in numpy)
    sent SIGTERM then SIGINT 0-10 ms apart exited 130, not 143: Python runs the pending handlers
    by signal number, SIGINT's first."""
    from cartctl import stopping

    previous = stopping.install()
    try:
        with pytest.raises(stopping.Interrupted) as raised:
            _burst_while_blocked(signal.SIGTERM, signal.SIGINT)
        assert raised.value.signum == signal.SIGTERM
        assert stopping.exit_code() == 143
    finally:
        stopping.restore(previous)


def test_monitor_the_first_signal_of_a_burst_counts() -> None:
    """``monitor`` has handlers of its own (stop after the frame): SIGTERM then SIGINT, run
    together, was taken for Ctrl-C first and exited 0 instead of 143."""
    from cartctl import stopping
    from cartctl.cli.commands.monitor import _stop_on_signals

    monitor, received = SimpleNamespace(stop_requested=False), []
    previous = stopping.install()
    try:
        with _stop_on_signals(monitor, received):  # type: ignore[arg-type]
            _burst_while_blocked(signal.SIGTERM, signal.SIGINT)
    finally:
        stopping.restore(previous)
    assert monitor.stop_requested
    assert received[0] == signal.SIGTERM


@pytest.mark.realtime
def test_monitor_a_signal_while_its_files_close_keeps_them_whole(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    rrd_rows: Callable[[Path], Any],
) -> None:
    """Once the monitor's own handlers are gone (its duration is over): the signal cut the
    closing short, the recording kept 20 of 100 frames, and no summary was printed."""
    import csv

    from cartctl.sinks.csv_sink import CsvSink

    monkeypatch.setattr(CsvSink, "close", _signalling(CsvSink.close))
    code = main(["monitor", "virtual", "--duration", "1", "--rerun", "save", "--out",
                 str(tmp_path), "--name", "m", "--json"])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 143, err
    assert "Traceback" not in err
    frames = json.loads(out)["frames"]
    with open(tmp_path / "m.csv", newline="", encoding="utf-8") as file:
        assert len(list(csv.reader(file))) == 1 + frames
    assert rrd_rows(tmp_path / "m.rrd")["gpio/speed_a"] == frames


def test_excite_a_signal_as_the_plant_closes_still_stops_the_motors(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """At the experiment's end the plant is closed (zero volts, a serial cart's stop frames): a
    signal there cut the closing short, the motors kept the last voltage of the signal (−10 V of
    the square wave) and the whole experiment was lost."""
    import cartctl.plants.factory as factory

    made: list[Any] = []
    original = factory.make_plant

    def make_plant(*args: Any, **kwargs: Any) -> Any:
        plant, description = original(*args, **kwargs)
        made.append(plant)
        plant.close = _signalling(plant.close)
        return plant, description

    monkeypatch.setattr(factory, "make_plant", make_plant)
    out = tmp_path / "x.csv"
    code = main(["excite", "--plant", "physics", "--amplitude", "10", "--cycles", "1",
                 "--out", str(out), "--json"])  # fmt: skip
    stdout, err = capsys.readouterr()
    assert code == 143
    assert len(_lines(err)) == 1 and "Traceback" not in err
    assert made[0].applied_voltage_v == (0.0, 0.0)
    assert len(read_trace(out)) == json.loads(stdout)["ticks"] == 300


def test_review_a_signal_a_library_turns_into_another_error_is_still_an_interruption(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """pyarrow's compute functions, stopped inside their compiled code, raised TypeError ('Got
    unexpected argument type <class 'int'> for compute function'): review printed a traceback and
    exited 1 after SIGHUP. Here a stand-in for that library turns the interrupt into that error."""
    from cartctl.cli.commands.review import smoothed

    assert main(["run", "--fast", "--duration", "0.5", "--name", "r"]) == 0
    capsys.readouterr()

    def scalar_series(*args: Any, **kwargs: Any) -> Any:
        try:
            os.kill(os.getpid(), signal.SIGHUP)
        except KeyboardInterrupt:
            raise TypeError("Got unexpected argument type <class 'int'>") from None

    monkeypatch.setattr(smoothed, "scalar_series", scalar_series)
    code = main(["review", "logs/r.rrd"])
    err = capsys.readouterr().err
    assert code == 129
    assert _lines(err) == ["cartctl review: interrupted"]


@pytest.mark.realtime
def test_review_screenshot_a_signal_once_the_viewer_started_stops_it(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The headless viewer runs in its own session (a terminal's Ctrl-C does not reach it): a
    signal between its start and the block that stops it left it running after cartctl exited."""
    import subprocess

    from cartctl.cli.commands.review import recording

    if not recording.vulkan_available():
        pytest.skip("--screenshot needs Vulkan (mesa-vulkan-drivers)")
    assert main(["run", "--fast", "--duration", "0.5", "--name", "r"]) == 0
    capsys.readouterr()
    started: list[subprocess.Popen[bytes]] = []

    class Popen(subprocess.Popen):  # type: ignore[type-arg]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            started.append(self)

    monkeypatch.setattr(subprocess, "Popen", Popen)
    monkeypatch.setattr(recording, "new_stream", _signalling(recording.new_stream))
    try:
        code = main(["review", "logs/r.rrd", "--screenshot", "shot.png"])
        err = capsys.readouterr().err
        assert code == 143
        assert _lines(err) == ["cartctl review: interrupted"]
        assert len(started) == 1 and started[0].poll() is not None  # stopped, not left running
    finally:
        for viewer in started:
            if viewer.poll() is None:
                os.killpg(viewer.pid, signal.SIGKILL)
                viewer.wait()


def test_commission_a_signal_in_its_verification_run_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The verification runs ``cartctl run`` in process: a signal after its loop gave the run's
    own 'cartctl run: stopped by SIGTERM' line and then commission's, naming the stage."""
    monkeypatch.setattr(run_command, "_summary", _signalling(run_command._summary))
    out = tmp_path / "c"
    code = main(["commission", "physics", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 143, err
    assert "Traceback" not in err
    assert not [line for line in _lines(err) if line.startswith("cartctl run:")], err
    assert "verification: interrupted; zero volts sent" in _lines(err)[-1]
    assert len(read_trace(out / "verification.csv")) > 100  # the run's trace, whole


def test_virtual_cart_a_signal_as_it_boots_still_switches_it_off(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``cartctl virtual-cart`` booted its cart with ``with cart:``: a signal raised inside the
    boot (``__enter__``) skipped ``__exit__``, and the cart ticked on ('stopped (running)')."""
    from cartctl.link.virtual_cart import VirtualCart

    carts: list[VirtualCart] = []
    original = VirtualCart.start

    def start(self: VirtualCart) -> None:
        carts.append(self)
        original(self)
        os.kill(os.getpid(), signal.SIGTERM)  # the threads started, the boot not yet returned

    monkeypatch.setattr(VirtualCart, "start", start)
    code = main(["virtual-cart", "--duration", "30"])
    err = capsys.readouterr().err
    assert code == 143, err
    assert "Traceback" not in err and "virtual cart stopped (stopped)" in err, err
    (cart,) = carts
    assert not cart._ticker.is_alive() and cart._master == -1  # off, its port closed


def test_a_forked_worker_does_not_take_the_parents_signal_order(stop_handlers) -> None:
    """``tune --jobs`` forks its workers with the handlers installed: a worker that took a Ctrl-C
    read the parent's pipe of signal numbers, took the SIGTERM byte that came first, and the
    parent then exited 130, not 143 (2 of 13 bursts)."""
    from cartctl import stopping

    os.write(stopping._order[1], bytes([signal.SIGTERM]))  # what the C handler writes on SIGTERM
    pid = os.fork()
    if pid == 0:  # the worker: its own order only
        os._exit(stopping.came_first(signal.SIGINT))
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == signal.SIGINT
    assert stopping.came_first(signal.SIGINT) == signal.SIGTERM  # the parent's, still there


class _ClosingTerminal:
    """stdout and stderr on a terminal that closes at its first write: SIGHUP to this process,
    then every write fails (EIO), as on a real hang-up."""

    def __init__(self) -> None:
        self.closed = False

    def isatty(self) -> bool:
        return True

    def write(self, text: str) -> int:
        if not self.closed:
            self.closed = True
            os.kill(os.getpid(), signal.SIGHUP)
        raise OSError(5, "Input/output error")

    def flush(self) -> None:
        if self.closed:
            raise OSError(5, "Input/output error")


@pytest.mark.parametrize(
    "argv",
    [
        ["excite", "--amplitude", "3", "--cycles", "1", "--out", "{tmp}/ex.csv"],  # progress bar
        ["run", "--fast", "--rerun", "off", "--duration", "1", "--out", "{tmp}", "--name", "ex"],
    ],
    ids=["excite", "run"],
)
def test_a_terminal_that_closes_keeps_the_trace_and_exits_129(
    argv: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Found closing the terminal of ``excite`` over serial: the progress bar's last write
    failed (EIO) after the experiment and the trace was never written; ``run`` exited 1 (its
    summary's print failed, then the error line's), not SIGHUP's 129."""
    terminal = _ClosingTerminal()
    monkeypatch.setattr("sys.stdout", terminal)
    monkeypatch.setattr("sys.stderr", terminal)
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    code = main([a.format(tmp=tmp_path) for a in argv])
    assert code == 129
    assert len(read_trace(tmp_path / "ex.csv")) > 0
    assert meta_path(tmp_path / "ex.csv").exists()


@pytest.mark.realtime  # the virtual cart behind a pseudo-terminal
def test_monitor_stopped_by_a_closing_terminal_exits_129(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The terminal closes at the monitor's fifth frame: it stops after that frame (its own
    handler took the SIGHUP) and its summary's print fails; it exited 2, a user's mistake."""
    from cartctl.link.cart_monitor import Monitor

    terminal, record = _ClosingTerminal(), Monitor._record

    def closing(self: Monitor, *args: Any) -> None:
        record(self, *args)
        if self.result.frames == 5:
            monkeypatch.setattr("sys.stdout", terminal)
            monkeypatch.setattr("sys.stderr", terminal)
            terminal.closed = True  # the hang-up: every write from now on fails, and SIGHUP
            os.kill(os.getpid(), signal.SIGHUP)

    monkeypatch.setattr(Monitor, "_record", closing)
    code = main(["monitor", "virtual", "--duration", "30", "--out", str(tmp_path), "--name", "m",
                 "--rerun", "off"])  # fmt: skip
    assert code == 129
    assert len(read_trace(tmp_path / "m.csv")) >= 5
