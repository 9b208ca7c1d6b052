"""A stop signal that lands in the middle of a tick ends the run after that tick, never inside it.

Python runs a signal handler between any two bytecodes of the main thread. When cartctl's handler
raised at once, a SIGTERM that came while the CSV sink formatted a row (after ``writerows``, before
the row was marked as formatted) had the row written twice: the trace read back with time standing
still (seen once in CI on ``test_stopping``). Here the signal is sent from inside the CSV sink's own
formatting, at a chosen tick, through each executor, with cartctl's real handlers installed: the
trace must hold every tick once, as many rows as the loop counted and the memory sink kept.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from cartctl import stopping
from cartctl.data.read import read_trace
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.plants.base import Measurement
from cartctl.plants.factory import make_plant
from cartctl.reference import reference_signal
from cartctl.runtime.executor import (
    BackToBackExecutor,
    CartClockedExecutor,
    PeriodicExecutor,
    SimulatedClock,
)
from cartctl.runtime.loop import ControlLoop, MemorySink
from cartctl.sinks.base import TRACE_COLUMNS
from cartctl.sinks.csv_sink import CsvSink

ROOT = Path(__file__).resolve().parents[1]
SIGNAL_AT_TICK = 37
TICKS = 200


class _SignalAfterWriterows:
    """Wraps a ``csv.writer``: sends SIGTERM to this process right after the rows of tick
    ``SIGNAL_AT_TICK`` are formatted, before the sink has noted them as formatted."""

    def __init__(self, writer: object) -> None:
        self.writer = writer
        self.sent = False

    def writerow(self, row: object) -> None:
        self.writer.writerow(row)  # type: ignore[attr-defined]

    def writerows(self, rows: list) -> None:
        self.writer.writerows(rows)  # type: ignore[attr-defined]
        if not self.sent and any(int(r[5]) == SIGNAL_AT_TICK for r in rows):  # column 5: tick
            self.sent = True
            os.kill(os.getpid(), signal.SIGTERM)


class _CartClocked:
    """The model simulator behind the cart-clocked interface: the command sent is applied when
    the next tick's measurement is received, one period later."""

    reports_true_speed = True

    def __init__(self, plant) -> None:
        self.plant, self.period_s = plant, plant.period_s
        self.arrival_s, self.tick_index = 0.0, 0
        self._command = (0.0, 0.0)

    def connect(self) -> None:
        pass

    def reset(self) -> Measurement:
        self.tick_index, self.arrival_s = 0, 0.0
        return self.plant.reset()

    def send(self, voltage_a_v: float, voltage_b_v: float) -> None:
        self._command = (voltage_a_v, voltage_b_v)

    def receive(self) -> Measurement:
        self.tick_index += 1
        self.arrival_s += self.period_s
        return self.plant.step(*self._command)

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        return self.plant.step(voltage_a_v, voltage_b_v)

    def close(self) -> None:
        self.plant.close()


@pytest.mark.parametrize("executor", ["periodic", "back-to-back", "cart-clocked"])
def test_a_signal_inside_the_csv_sink_ends_the_run_after_that_tick(
    tmp_path: Path, executor: str, stop_handlers
) -> None:
    controllers = build_controllers(load_controller(ROOT / "controllers" / "pi.toml"))
    plant, _ = make_plant("sim")
    if executor == "cart-clocked":
        plant = _CartClocked(plant)
    reference = reference_signal("step:8", TICKS, plant.period_s)
    csv_sink, memory, clock = (
        CsvSink(tmp_path / "s.csv", flush_every=10),
        MemorySink(),
        SimulatedClock(),
    )
    csv_sink._writer = _SignalAfterWriterows(csv_sink._writer)
    loop = ControlLoop(plant, controllers, {"a": reference, "b": reference}, [csv_sink, memory],
                       now_s=clock.now_s)  # fmt: skip

    loop.start()
    if executor == "periodic":
        ex = PeriodicExecutor(plant.period_s, clock, max_ticks=TICKS)
        run = lambda: ex.run(lambda k: loop.tick(k, ex.period_error_us, ex.start_s), loop.idle)  # noqa: E731
    elif executor == "back-to-back":
        ex = BackToBackExecutor(plant.period_s, max_ticks=TICKS, idle_every=1)
        run = lambda: ex.run(lambda k: loop.tick(k, 0.0, 0.0), loop.idle)  # noqa: E731
    else:
        ex = CartClockedExecutor(plant, max_ticks=TICKS, now_s=clock.now_s,
                                 compute_us=lambda: loop.last_compute_us)  # fmt: skip
        run = lambda: ex.run(lambda k: loop.tick(k, 0.0, 0.0, ex.time_s))  # noqa: E731
    with pytest.raises(stopping.Interrupted) as raised:
        run()
    with stopping.deferred():
        loop.finish()
    assert raised.value.signum == signal.SIGTERM
    assert csv_sink._writer.sent

    trace = read_trace(tmp_path / "s.csv")  # refuses time that stands still
    assert len(trace) == loop.state.rows == SIGNAL_AT_TICK + 2  # the ticks and the stop row
    assert np.all(np.diff(trace.time_s) > 0)
    kept = memory.arrays()
    np.testing.assert_array_equal(trace.time_s, kept["time_s"])
    np.testing.assert_array_equal(trace.voltage_a, kept["voltage_a"])
    assert (trace.voltage_a[-1], trace.voltage_b[-1]) == (0.0, 0.0)
    stats = ex.stats()  # whole ticks only: one period error and one compute time each
    assert stats.ticks == SIGNAL_AT_TICK + 1


class _InterruptAfterWriterows(_SignalAfterWriterows):
    """Raises KeyboardInterrupt right after the rows of tick ``SIGNAL_AT_TICK`` are formatted: a
    Ctrl-C with Python's own handler (``monitor``'s second Ctrl-C, a script's loop)."""

    def writerows(self, rows: list) -> None:
        self.writer.writerows(rows)  # type: ignore[attr-defined]
        if not self.sent and any(int(r[5]) == SIGNAL_AT_TICK for r in rows):
            self.sent = True
            raise KeyboardInterrupt


def test_a_csv_sink_interrupted_inside_its_formatting_never_writes_a_row_twice(
    tmp_path: Path,
) -> None:
    """Outside a held tick, an interrupt may cost the row being formatted, never duplicate it (a
    trace with a row twice does not read back at all)."""
    sink = CsvSink(tmp_path / "s.csv", flush_every=10)
    sink.open(TRACE_COLUMNS)
    sink._writer = _InterruptAfterWriterows(sink._writer)

    def record() -> None:
        for k in range(TICKS):
            sink.write((k * 0.01, 1.0, 1.0, 2.0, 2.0, k, 3.0, 3.0, 2.0, 2.0, 0.0, 5.0))
            sink.idle()

    with pytest.raises(KeyboardInterrupt):
        record()
    sink.close()
    trace = read_trace(tmp_path / "s.csv")
    assert len(trace) == SIGNAL_AT_TICK + 1
    np.testing.assert_array_equal(trace.time_s, np.arange(SIGNAL_AT_TICK + 1) * 0.01)


def test_a_memory_sink_interrupted_while_packing_never_keeps_a_row_twice() -> None:
    memory = MemorySink()
    memory.open(("time_s", "tick"))
    rows = [(k * 0.01, float(k)) for k in range(5)]
    for row in rows:
        memory.write(row)

    class Interrupting(list):
        raised = False

        def __iter__(self):
            yield from super().__iter__()
            if not Interrupting.raised:  # after the last row is packed, before it is let go
                Interrupting.raised = True
                raise KeyboardInterrupt

    memory._rows = Interrupting(memory._rows)
    with pytest.raises(KeyboardInterrupt):
        memory.idle()
    np.testing.assert_array_equal(memory.arrays()["tick"], np.arange(5.0))


class _SignalOnOpen:
    """A sink that sends SIGTERM to this process as it opens (before the sinks after it do)."""

    def open(self, columns) -> None:
        os.kill(os.getpid(), signal.SIGTERM)

    def write(self, row) -> None:
        pass

    def close(self) -> None:
        pass


def test_a_signal_while_the_sinks_open_waits_until_every_file_has_its_header(
    tmp_path: Path, stop_handlers
) -> None:
    controllers = build_controllers(load_controller(ROOT / "controllers" / "pi.toml"))
    plant, _ = make_plant("sim")
    csv_sink, clock = CsvSink(tmp_path / "s.csv"), SimulatedClock()
    loop = ControlLoop(plant, controllers, {"a": [8.0] * 10, "b": [8.0] * 10},
                       [_SignalOnOpen(), csv_sink], now_s=clock.now_s)  # fmt: skip
    with pytest.raises(stopping.Interrupted):
        loop.start()
    with stopping.deferred():
        loop.finish()
    assert loop.state.sink_errors == []
    trace = read_trace(tmp_path / "s.csv")  # the header, then the stop row
    assert len(trace) == loop.state.rows == 1
    assert (trace.voltage_a[0], trace.voltage_b[0]) == (0.0, 0.0)


def test_a_signal_while_a_cart_clocked_loop_starts_still_leaves_the_stop_row(
    tmp_path: Path, stop_handlers
) -> None:
    """A cart's first measurement comes after the sinks open (so that their start-up does not put
    the loop behind the cart): a signal while they opened was raised before it, and the trace
    held its header alone, which read_trace refuses ('no data rows'; seen in ``run --plant
    virtual`` stopped at random moments)."""
    controllers = build_controllers(load_controller(ROOT / "controllers" / "pi.toml"))
    plant, _ = make_plant("sim")
    csv_sink, clock = CsvSink(tmp_path / "s.csv"), SimulatedClock()
    loop = ControlLoop(_CartClocked(plant), controllers, {"a": [8.0] * 10, "b": [8.0] * 10},
                       [_SignalOnOpen(), csv_sink], now_s=clock.now_s)  # fmt: skip
    with pytest.raises(stopping.Interrupted):
        loop.start()
    with stopping.deferred():
        loop.finish()
    trace = read_trace(tmp_path / "s.csv")  # the header, then the stop row
    assert len(trace) == loop.state.rows == 1
    assert (trace.voltage_a[0], trace.voltage_b[0]) == (0.0, 0.0)


def test_a_block_held_in_another_thread_leaves_the_signal_to_the_main_one(stop_handlers) -> None:
    """Python runs the handlers in the main thread: a block held in another thread (a plant closed
    there) must not hold the main thread's signal, nor raise it in its own thread."""
    import threading

    inside, release = threading.Event(), threading.Event()
    raised_in_thread: list[BaseException] = []

    def close_elsewhere() -> None:
        try:
            with stopping.held():
                inside.set()
                release.wait(5.0)
        except BaseException as exc:  # what the thread would have raised
            raised_in_thread.append(exc)

    worker = threading.Thread(target=close_elsewhere)
    worker.start()
    assert inside.wait(5.0)
    try:
        with pytest.raises(stopping.Interrupted):
            os.kill(os.getpid(), signal.SIGTERM)
    finally:
        release.set()
        worker.join(5.0)
    assert raised_in_thread == []
