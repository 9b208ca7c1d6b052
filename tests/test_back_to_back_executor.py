"""The fast loop's executor: ticks back to back, idle in blocks, the same trace as the periodic one."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.errors import InputError
from cartctl.plants.factory import make_plant
from cartctl.reference import reference_signal
from cartctl.runtime.executor import BackToBackExecutor, PeriodicExecutor, SimulatedClock
from cartctl.runtime.loop import ControlLoop, MemorySink


def test_runs_max_ticks_and_idles_every_block_and_at_the_end() -> None:
    seen: list[int] = []
    idles: list[int] = []
    ex = BackToBackExecutor(0.01, max_ticks=2500, idle_every=1000)
    stats = ex.run(lambda k: seen.append(k) is None, lambda: idles.append(len(seen)))
    assert seen == list(range(2500))
    assert idles == [1000, 2000, 2500]
    assert (stats.ticks, stats.misses, stats.skipped_deadlines) == (2500, 0, 0)
    assert stats.compute_us_max == 0.0 and stats.period_error_us_max == 0.0
    assert stats.duration_s == pytest.approx(2499 * 0.01)


def test_stops_after_a_false_tick_and_counts_ticks_before_an_exception() -> None:
    ex = BackToBackExecutor(0.01, max_ticks=100, idle_every=7)
    idles: list[int] = []
    assert ex.run(lambda k: k < 9, lambda: idles.append(ex.ticks)).ticks == 10
    assert idles == [7, 10]  # the block, then the end of the run

    def boom(k: int) -> bool:
        if k == 5:
            raise RuntimeError("plant fault")
        return True

    with pytest.raises(RuntimeError):
        ex.run(boom)
    assert ex.stats().ticks == 5


@pytest.mark.parametrize(
    "kwargs",
    [{"period_s": 0.0, "max_ticks": 1}, {"period_s": 0.01, "max_ticks": -1},
     {"period_s": 0.01, "max_ticks": 1, "idle_every": 0}],
)  # fmt: skip
def test_bad_arguments(kwargs: dict) -> None:
    with pytest.raises(InputError):
        BackToBackExecutor(**kwargs)


def _trace(executor: str, plant_spec: str, controller: str) -> dict[str, np.ndarray]:
    """The shipped controller on a simulated plant for 3 s, through one executor or the other."""
    ctrl = load_controller(controller)
    plant, _ = make_plant(plant_spec)
    n = 300
    ref = reference_signal("square:8:1", n, plant.period_s)
    memory, clock = MemorySink(), SimulatedClock()
    loop = ControlLoop(plant, build_controllers(ctrl), {"a": ref, "b": -ref}, [memory],
                       now_s=clock.now_s, voltage_limit_v=ctrl.voltage_limit_v)  # fmt: skip
    loop.start()
    if executor == "back-to-back":
        BackToBackExecutor(0.01, max_ticks=n, idle_every=64).run(
            lambda k: loop.tick(k, 0.0, 0.0, k * 0.01), loop.idle
        )
    else:
        ex = PeriodicExecutor(0.01, clock, max_ticks=n)
        ex.run(lambda k: loop.tick(k, ex.period_error_us, ex.start_s, ex.grid_index * 0.01),
               loop.idle)  # fmt: skip
    loop.finish()
    return memory.arrays()


@pytest.mark.parametrize(
    ("plant", "controller"),
    [("sim", "controllers/pi.toml"), ("physics", "controllers/poles.toml")],
)
def test_same_trace_as_the_periodic_executor_on_a_simulated_clock(
    plant: str, controller: str
) -> None:
    a, b = _trace("back-to-back", plant, controller), _trace("periodic", plant, controller)
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert np.abs(a["voltage_a"]).max() > 1.0  # the loop did something


def test_run_fast_writes_every_tick_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """2500 ticks: two whole idle blocks and a part; the CSV holds each tick once, in order."""
    code = main(["run", "--fast", "--duration", "25", "--rerun", "off", "--out", str(tmp_path),
                 "--json"])  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    header = Path(summary["trace"]).read_text().splitlines()[0].split(",")
    table = np.loadtxt(summary["trace"], delimiter=",", skiprows=1)
    ticks, time_s = table[:, header.index("tick")], table[:, header.index("time_s")]
    assert summary["ticks"] == len(ticks) == 2501  # the stop row included
    np.testing.assert_array_equal(ticks, np.arange(2501))
    np.testing.assert_allclose(np.diff(time_s), 0.01, rtol=1e-9)
    assert summary["deadline_misses"] == 0
