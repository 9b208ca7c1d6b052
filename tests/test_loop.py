"""The loop core: tick order, clamping, safety on every exit path, the CSV trace and the summary."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from cartctl.data.read import read_trace
from cartctl.errors import CartctlError, DataWarning, PlantError
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.reference import reference_signal
from cartctl.runtime.loop import ControlLoop, MemorySink
from cartctl.runtime.pi import PiController
from cartctl.sinks.base import TRACE_COLUMNS
from cartctl.sinks.csv_sink import CsvSink
from cartctl.sinks.summary import trace_metrics

MODEL = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751])


class RecordingPlant(ArxPlant):
    """The ARX plant, remembering every command and failing on request."""

    def __init__(self, fail_at: int | None = None, interrupt_at: int | None = None) -> None:
        super().__init__(MODEL, MODEL)
        self.commands: list[tuple[float, float]] = []
        self.fail_at, self.interrupt_at = fail_at, interrupt_at
        self.closed = False

    def step(self, voltage_a_v: float, voltage_b_v: float):
        if self.fail_at is not None and len(self.commands) == self.fail_at:
            self.fail_at = None
            raise PlantError("the cable was pulled")
        if self.interrupt_at is not None and len(self.commands) == self.interrupt_at:
            self.interrupt_at = None
            raise KeyboardInterrupt
        self.commands.append((voltage_a_v, voltage_b_v))
        return super().step(voltage_a_v, voltage_b_v)

    def close(self) -> None:
        self.closed = True


def _loop(
    plant, n: int, sinks, kp: float = 0.2, ki: float = 13.0, limit: float = 12.0
) -> ControlLoop:
    refs = {m: reference_signal("step:10:0.1", n) for m in "ab"}
    ctrls = {m: PiController(kp, ki, 0.01) for m in "ab"}
    return ControlLoop(plant, ctrls, refs, sinks, now_s=lambda: 0.0, voltage_limit_v=limit)


def _run(loop: ControlLoop) -> None:
    loop.start()
    try:
        k = 0
        while loop.tick(k, 0.0, 0.0):
            k += 1
    finally:
        loop.finish()


def test_trace_rows_follow_the_trace_columns(tmp_path: Path) -> None:
    memory = MemorySink()
    plant = RecordingPlant()
    _run(_loop(plant, 200, [CsvSink(tmp_path / "t.csv", flush_every=7), memory]))
    trace = read_trace(tmp_path / "t.csv")
    assert len(trace) == 201  # 200 ticks and the stop row
    assert tuple(trace.columns())[: len(TRACE_COLUMNS)] == TRACE_COLUMNS
    np.testing.assert_array_equal(trace.column("tick"), np.arange(201))
    assert (trace.voltage_a[-1], trace.voltage_b[-1]) == (0.0, 0.0)  # the stop command, logged
    assert trace.voltage_a[-2] != 0.0
    # row k: the voltage commanded at tick k and the speed measured at tick k
    np.testing.assert_allclose(trace.speed_a, MODEL.simulate(trace.voltage_a), atol=1e-12)
    cols = memory.arrays()
    np.testing.assert_array_equal(cols["voltage_a"], trace.voltage_a)  # CSV is exact
    assert plant.commands[-1] == (0.0, 0.0)  # finish sends zero volts
    assert plant.closed


def test_voltage_is_clamped_to_the_limit() -> None:
    memory = MemorySink()
    _run(_loop(RecordingPlant(), 100, [memory], kp=50.0, limit=6.0))
    volts = memory.arrays()["voltage_a"]
    assert np.max(np.abs(volts)) == pytest.approx(6.0)


@pytest.mark.parametrize("fault", ["fail", "interrupt"])
def test_faults_leave_zero_volts_and_valid_files(tmp_path: Path, fault: str) -> None:
    plant = RecordingPlant(fail_at=120) if fault == "fail" else RecordingPlant(interrupt_at=120)
    loop = _loop(plant, 300, [CsvSink(tmp_path / "t.csv")])
    with pytest.raises(PlantError if fault == "fail" else KeyboardInterrupt):
        _run(loop)
    assert plant.commands[-1] == (0.0, 0.0)
    assert plant.closed
    trace = read_trace(tmp_path / "t.csv")
    assert len(trace) == 121  # every tick up to the fault, none lost, then the stop row
    assert loop.state.rows == 121
    assert trace.column("tick")[-1] == 120 and trace.voltage_a[-1] == 0.0


def test_summary_of_a_step() -> None:
    memory = MemorySink()
    _run(_loop(RecordingPlant(), 300, [memory]))
    summary = trace_metrics(memory.arrays(), 0.01)
    a = summary["motors"]["a"]
    assert summary["ticks"] == 301  # and the stop row
    assert a["overshoot_percent"] < 5.0
    assert abs(a["steady_state_error"]) < 1e-3
    assert 0.0 < a["rise_time_s"] < a["settling_time_s"] < 1.0
    assert a["max_abs_voltage"] <= 12.0
    assert summary["deadline_misses"] == 0


@pytest.mark.parametrize(
    ("spec", "check"),
    [
        ("step:10", lambda r: r[49] == 0 and r[50] == 10),
        ("step:-5:0", lambda r: r[0] == -5),
        ("square:8:2", lambda r: r[0] == 8 and r[100] == -8 and r[200] == 8),
        ("ramp:4:6", lambda r: r[100] == pytest.approx(4) and r.max() == 6),
        ("const:3", lambda r: (r == 3).all()),
    ],
)
def test_reference_specs(spec: str, check) -> None:
    assert check(reference_signal(spec, 500))


def test_reference_from_file(tmp_path: Path) -> None:
    path = tmp_path / "ref.csv"
    path.write_text("time_s,reference_a,reference_b\n0,0,0\n1,10,-10\n")
    ra = reference_signal(f"file:{path}", 200, motor="a")
    rb = reference_signal(f"file:{path}", 200, motor="b")
    assert ra[50] == pytest.approx(5.0)
    assert rb[150] == pytest.approx(-10.0)


@pytest.mark.parametrize(
    "spec", ["sine:3", "step:x", "square:5", "square:5:0.01", "file:/nope.csv"]
)
def test_bad_references(spec: str) -> None:
    with pytest.raises(CartctlError):
        reference_signal(spec, 100)


def _run_with_idle(loop: ControlLoop, idle_at: set[int] | None = None) -> list[int]:
    """As the executor runs a loop: tick, then idle (on every tick, or on those in idle_at)."""
    lines = []
    loop.start()
    try:
        k = 0
        while True:
            more = loop.tick(k, 0.0, 0.0)
            if idle_at is None or k in idle_at:
                loop.idle()
            lines.append(k)
            if not more:
                break
            k += 1
    finally:
        loop.finish()
    return lines


@pytest.mark.parametrize("idle_at", [None, set(range(0, 300, 7)), set()])
def test_sinks_hold_every_row_whenever_idle_runs(tmp_path: Path, idle_at: set[int] | None) -> None:
    """Rows kept by write() and packed or formatted in idle() lose nothing and change nothing."""
    memory, plain = MemorySink(), []

    class ListSink:
        def open(self, columns):
            pass

        def write(self, row):
            plain.append(tuple(row))

        def close(self):
            pass

    sinks = [CsvSink(tmp_path / "t.csv", flush_every=50), memory, ListSink()]
    _run_with_idle(_loop(RecordingPlant(), 300, sinks), idle_at)
    expected = np.array(plain)  # the rows as the loop made them, kept by a sink with no idle
    assert expected.shape[0] == 301
    trace = read_trace(tmp_path / "t.csv")
    np.testing.assert_array_equal(trace.voltage_a, expected[:, 1])
    np.testing.assert_array_equal(trace.column("tick"), expected[:, 5])
    np.testing.assert_array_equal(np.column_stack(list(memory.arrays().values())), expected)


def test_csv_rows_reach_the_file_a_block_at_a_time_with_idle(tmp_path: Path) -> None:
    sink = CsvSink(tmp_path / "t.csv", flush_every=50)
    sink.open(["a", "b"])
    lines = lambda: (tmp_path / "t.csv").read_text().count("\n")  # noqa: E731
    for i in range(49):
        sink.write((float(i), 1.5))
        sink.idle()
    assert lines() == 1  # the header: the block is not complete
    sink.write((49.0, 1.5))
    assert lines() == 1  # write() alone formats nothing
    sink.idle()
    assert lines() == 51  # one block of 50, flushed: a crash from here loses nothing
    sink.close()


class _SkippingCart:
    """A physics plant paced like a cart over serial whose frames of cart ticks 4 and 7 were lost:
    its ``tick_index`` jumps there, as :class:`~cartctl.link.serial_cart.SerialCart`'s does."""

    def __init__(self, plant, description: str) -> None:
        self.plant, self.description = plant, description
        self.period_s, self.tick_index, self._row = plant.period_s, 0, 0
        self.loop_delay_ticks = 1

    def reset(self):
        self.tick_index = self._row = 0
        return self.plant.reset()

    def step(self, voltage_a_v: float, voltage_b_v: float):
        self._row += 1
        self.tick_index += 2 if self._row in (4, 6) else 1
        return self.plant.step(voltage_a_v, voltage_b_v)

    def close(self) -> None:
        self.plant.close()


def test_an_excitation_keeps_the_cart_ticks_it_lost(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``excite`` over serial writes each row at its cart tick, as ``run`` and ``monitor`` do (it
    wrote k·Ts, so a lost frame vanished from the trace and ``identify`` could not warn of it)."""
    import cartctl.plants.factory as factory
    from cartctl.cli import main

    make = factory.make_plant

    def skipping(spec: str, **options):
        cart = _SkippingCart(*make(spec, **options))
        return cart, cart.description

    monkeypatch.setattr(factory, "make_plant", skipping)
    out = tmp_path / "e.csv"
    assert main(["excite", "--plant", "physics", "--amplitude", "6", "--out", str(out)]) == 0
    with pytest.warns(DataWarning, match=r"about 2 row\(s\) are missing"):
        time_s = read_trace(out).columns()["time_s"]
    steps = np.round(np.diff(time_s) / 0.01).astype(int)
    assert list(np.flatnonzero(steps == 2)) == [3, 5] and np.all(steps[steps != 2] == 1)
    capsys.readouterr()
    with warnings.catch_warnings():  # as on the command line: one line on stderr
        warnings.simplefilter("always")
        assert main(["identify", str(out)]) == 0
    assert "about 2 row(s) are missing" in capsys.readouterr().err
