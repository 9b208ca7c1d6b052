"""The periodic executor on a simulated clock: grid, statistics, misses, stopping; one real-clock run."""

from __future__ import annotations

import logging
import os
import time

import numpy as np
import pytest

from cartctl.errors import InputError
from cartctl.runtime import realtime
from cartctl.runtime.executor import (
    MISS_LOG_LIMIT,
    Clock,
    MonotonicClock,
    PeriodicExecutor,
    SimulatedClock,
    TimingStats,
)


class LateClock(SimulatedClock):
    """A simulated clock that wakes up late by a given amount (s) at each wait, in turn."""

    def __init__(self, lateness_s: list[float]) -> None:
        super().__init__()
        self.lateness_s = list(lateness_s)
        self.waits = 0

    def wait_until(self, deadline_s: float) -> None:
        super().wait_until(deadline_s)
        self.advance(self.lateness_s[self.waits % len(self.lateness_s)])
        self.waits += 1


def test_clocks_satisfy_the_protocol() -> None:
    assert isinstance(SimulatedClock(), Clock)
    assert isinstance(MonotonicClock(), Clock)


def test_simulated_clock_jumps_forward_only() -> None:
    c = SimulatedClock(2.0)
    c.wait_until(3.5)
    assert c.now_s() == 3.5
    c.wait_until(1.0)  # a past deadline: no change
    assert c.now_s() == 3.5
    c.advance(0.25)
    assert c.now_s() == 3.75
    with pytest.raises(InputError, match="dt_s"):
        c.advance(-0.1)


@pytest.mark.parametrize("start_s", [0.0, 5.0, 12345.678])
def test_ticks_start_exactly_on_the_grid(start_s: float) -> None:
    clock = SimulatedClock(start_s)
    ex = PeriodicExecutor(0.01, clock, max_ticks=1000)
    seen: list[tuple[int, float, float, int, float]] = []

    def tick(k: int) -> bool:
        seen.append((k, clock.now_s(), ex.deadline_s, ex.grid_index, ex.period_error_us))
        return True

    stats = ex.run(tick)
    assert stats.ticks == 1000
    assert ex.t0_s == start_s
    for k, now_s, deadline_s, m, err_us in seen:
        assert now_s == deadline_s == start_s + k * 0.01  # computed from t0: no accumulated drift
        assert m == k
        assert err_us == 0.0
    assert [s[0] for s in seen] == list(range(1000))


def test_stats_of_a_clean_simulated_run() -> None:
    stats = PeriodicExecutor(0.01, SimulatedClock(), max_ticks=100).run(lambda k: True)
    assert (stats.ticks, stats.misses, stats.skipped_deadlines, stats.miss_ticks) == (100, 0, 0, ())
    assert stats.duration_s == pytest.approx(0.99)
    assert stats.period_error_us_max == 0.0
    assert stats.compute_us_max == 0.0
    d = stats.to_dict()
    assert d["deadline_misses"] == 0
    assert set(d["period_error_us"]) == {"p50", "p99", "max"}
    assert {"p50", "p99"} <= set(d["compute_us"])


def test_period_error_and_compute_statistics() -> None:
    rng = np.random.default_rng(7)
    n = 500
    lateness_s = rng.uniform(0.0, 200e-6, n)
    compute_s = rng.uniform(50e-6, 2e-3, n)
    clock = LateClock(list(lateness_s))
    ex = PeriodicExecutor(0.01, clock, max_ticks=n)
    seen_err_us: list[float] = []

    def tick(k: int) -> bool:
        seen_err_us.append(ex.period_error_us)
        clock.advance(compute_s[k])
        return True

    stats = ex.run(tick)
    assert stats.misses == 0
    np.testing.assert_allclose(seen_err_us, lateness_s * 1e6, rtol=0, atol=1e-6)
    err_us, cu_us = lateness_s * 1e6, compute_s * 1e6
    assert stats.period_error_us_p50 == pytest.approx(np.percentile(err_us, 50), abs=1e-6)
    assert stats.period_error_us_p99 == pytest.approx(np.percentile(err_us, 99), abs=1e-6)
    assert stats.period_error_us_max == pytest.approx(err_us.max(), abs=1e-6)
    assert stats.compute_us_p50 == pytest.approx(np.percentile(cu_us, 50), abs=1e-6)
    assert stats.compute_us_p99 == pytest.approx(np.percentile(cu_us, 99), abs=1e-6)
    assert stats.compute_us_max == pytest.approx(cu_us.max(), abs=1e-6)
    d = stats.to_dict()
    assert d["period_error_us"]["p99"] == stats.period_error_us_p99
    assert d["compute_us"]["p50"] == stats.compute_us_p50


# period 0.25 s (exact in binary); tick 2 starts at 0.5 s and takes `work_s`
@pytest.mark.parametrize(
    ("work_s", "miss", "skipped", "next_grid"),
    [
        (0.125, False, 0, 3),  # well inside the period
        (0.25, False, 0, 3),  # ends exactly at the next deadline: not past it
        (0.375, True, 1, 4),  # past grid 3 (0.75 s); grid 4 (1.0 s) is still ahead
        (0.5, True, 1, 4),  # ends exactly on grid 4: starts there, on time
        (1.0625, True, 4, 7),  # past grids 3..6
    ],
)
def test_slow_tick_is_a_miss_and_realigns_to_the_grid(
    work_s: float, miss: bool, skipped: int, next_grid: int, caplog: pytest.LogCaptureFixture
) -> None:
    period_s = 0.25
    clock = SimulatedClock()
    ex = PeriodicExecutor(period_s, clock, max_ticks=8)
    starts: list[tuple[int, float]] = []

    def tick(k: int) -> bool:
        starts.append((ex.grid_index, clock.now_s()))
        if k == 2:
            clock.advance(work_s)
        return True

    with caplog.at_level(logging.WARNING, logger="cartctl.runtime.executor"):
        stats = ex.run(tick)

    assert stats.ticks == 8  # no tick is dropped: the skipped grid points are counted instead
    assert stats.misses == int(miss)
    assert stats.miss_ticks == ((2,) if miss else ())
    assert stats.skipped_deadlines == skipped
    grid = [m for m, _ in starts]
    assert grid == [0, 1, 2, *range(next_grid, next_grid + 5)]
    for m, now_s in starts:
        assert now_s == m * period_s  # back on the grid, no drift
    assert ("deadline miss: tick 2" in caplog.text) == miss


def test_every_miss_is_counted_beyond_the_log_limit(caplog: pytest.LogCaptureFixture) -> None:
    clock = SimulatedClock()
    ex = PeriodicExecutor(0.01, clock, max_ticks=100)

    def tick(k: int) -> bool:
        clock.advance(0.015)  # every tick overruns into the next period
        return True

    with caplog.at_level(logging.WARNING, logger="cartctl.runtime.executor"):
        stats = ex.run(tick)
    assert stats.misses == 99  # the last tick waits for no further deadline
    assert stats.skipped_deadlines == 99
    assert stats.miss_ticks == tuple(range(99))
    individual = [r for r in caplog.records if "deadline miss:" in r.getMessage()]
    assert len(individual) == MISS_LOG_LIMIT
    assert "99 deadline misses in 100 ticks (99 deadlines skipped)" in caplog.text


def test_stops_after_the_tick_that_returns_false() -> None:
    ticks: list[int] = []

    def tick(k: int) -> bool:
        ticks.append(k)
        return k < 4

    stats = PeriodicExecutor(0.01, SimulatedClock()).run(tick)
    assert ticks == [0, 1, 2, 3, 4]
    assert stats.ticks == 5


@pytest.mark.parametrize("n", [0, 1, 7])
def test_max_ticks(n: int) -> None:
    stats = PeriodicExecutor(0.01, SimulatedClock(), max_ticks=n).run(lambda k: True)
    assert stats.ticks == n


def test_empty_run_gives_null_percentiles() -> None:
    d = PeriodicExecutor(0.01, SimulatedClock(), max_ticks=0).run(lambda k: True).to_dict()
    assert d["ticks"] == 0
    assert d["period_error_us"] == {"p50": None, "p99": None, "max": None}
    assert d["compute_us"]["p50"] is None


def test_exception_in_tick_propagates_and_keeps_the_stats() -> None:
    def tick(k: int) -> bool:
        if k == 3:
            raise RuntimeError("plant vanished")
        return True

    ex = PeriodicExecutor(0.01, SimulatedClock())
    with pytest.raises(RuntimeError, match="plant vanished"):
        ex.run(tick)
    assert ex.stats().ticks == 3


def test_each_run_starts_afresh() -> None:
    clock = SimulatedClock()
    ex = PeriodicExecutor(0.5, clock, max_ticks=3)
    ex.run(lambda k: True)
    assert ex.t0_s == 0.0
    stats = ex.run(lambda k: True)
    assert ex.t0_s == 1.0  # the new grid starts where the clock is now
    assert stats.ticks == 3


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"period_s": 0.0}, "period_s"),
        ({"period_s": float("nan")}, "period_s"),
        ({"max_ticks": -1}, "max_ticks"),
        ({"max_ticks": 2.5}, "max_ticks"),
        ({"clock": object()}, "clock"),
    ],
)
def test_bad_arguments_name_the_parameter(kwargs: dict[str, object], match: str) -> None:
    args: dict[str, object] = {"period_s": 0.01, "clock": SimulatedClock(), **kwargs}
    with pytest.raises(ValueError, match=match):
        PeriodicExecutor(**args)  # type: ignore[arg-type]


def test_timing_stats_from_samples_checks_shapes() -> None:
    with pytest.raises(InputError, match="equally long"):
        TimingStats.from_samples(np.zeros(3), np.zeros(4), period_s=0.01)


def test_monotonic_clock_rejects_negative_spin() -> None:
    with pytest.raises(InputError, match="spin_s"):
        MonotonicClock(spin_s=-0.001)


@pytest.mark.realtime
def test_monotonic_clock_runs_the_grid_in_real_time() -> None:
    """The one real-time test: 20 ticks at 10 ms wait for their deadlines, so they never finish
    early (a loaded machine only makes them late; how late: ``benchmarks/bench_speeds.py``)."""
    ex = PeriodicExecutor(0.01, MonotonicClock(), max_ticks=20)
    t = time.perf_counter()
    stats = ex.run(lambda k: True)
    elapsed_s = time.perf_counter() - t
    assert elapsed_s >= 0.19  # tick 0 at once, tick 19 at 190 ms at the earliest
    assert stats.ticks == 20
    assert stats.period_error_us_p50 >= 0.0


def test_realtime_falls_back_with_a_reason(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    text = realtime.enable_realtime(50)
    assert text.startswith("normal scheduling: SCHED_FIFO not permitted")
    assert "Operation not permitted" in text
    realtime.restore()  # nothing obtained: nothing to undo, and no error


def test_realtime_enable_and_restore() -> None:
    if not hasattr(os, "sched_setscheduler"):
        pytest.skip("no sched_setscheduler on this platform")
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    with realtime.realtime_scheduling(10, lock_memory=False) as text:
        assert text.startswith(("SCHED_FIFO priority 10", "normal scheduling:"))
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before


def test_realtime_rejects_a_bad_priority() -> None:
    if not hasattr(os, "sched_setscheduler"):
        pytest.skip("no sched_setscheduler on this platform")
    with pytest.raises(InputError, match="priority"):
        realtime.enable_realtime(1000)


def test_idle_runs_after_each_tick_outside_its_compute_time() -> None:
    clock = SimulatedClock()
    calls: list[tuple[str, int]] = []
    ex = PeriodicExecutor(0.01, clock, max_ticks=5)

    def tick(k: int) -> bool:
        calls.append(("tick", k))
        clock.advance(0.002)  # 2 ms of work
        return True

    def idle() -> None:
        calls.append(("idle", ex.tick_index))
        clock.advance(0.003)  # 3 ms more that must not count as the tick's

    stats = ex.run(tick, idle)
    assert calls == [(what, k) for k in range(5) for what in ("tick", "idle")]
    assert stats.compute_us_max == pytest.approx(2000.0)
    assert stats.misses == 0 and stats.period_error_us_max == 0.0  # 5 ms < the 10 ms period


def test_gc_paused_freezes_and_restores() -> None:
    import gc

    from cartctl.runtime.realtime import gc_paused

    seen: list[tuple[bool, int]] = []

    def fault_inside_the_run() -> None:
        with gc_paused():
            seen.append((gc.isenabled(), gc.get_freeze_count()))
            raise RuntimeError("a fault inside the run")

    assert gc.isenabled()
    with pytest.raises(RuntimeError):
        fault_inside_the_run()
    ((enabled, frozen),) = seen
    assert not enabled and frozen > 0  # the heap from before: no collection walks it
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_gc_paused_leaves_the_switch_interval_it_did_not_set() -> None:
    """run sets the 0.1 ms GIL hand-over itself, to last through loop.finish()'s zero volts:
    a plain pause must leave it as it is. Restoring it anyway went through a float round trip
    (1e-4 s read back as 99.99... µs) and left 99 µs for the shutdown (371bf52)."""
    import sys

    from cartctl.runtime.realtime import gc_paused

    before = sys.getswitchinterval()
    try:
        sys.setswitchinterval(1e-4)  # as run's loop, before its pause
        expected = sys.getswitchinterval()
        with gc_paused():
            pass
        assert sys.getswitchinterval() == expected
        with gc_paused(quick_gil=True):  # excite's: its own set, undone on the way out
            assert sys.getswitchinterval() < 2e-4
    finally:
        sys.setswitchinterval(before)
