"""The fast simulated loop (``run --fast``, ``tune``, the Python API): ticks back to back.

The real-time run's :class:`~cartctl.runtime.loop.ControlLoop`, but every tick starts on its grid
point (period error 0), takes no simulated time and cannot miss, and the sinks' block work
(``idle``) runs every :attr:`~BackToBackExecutor.idle_every` ticks, not after each (about a
quarter of the fast loop's time, ``benchmarks/bench_run.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import PlantError
from cartctl.plants.base import Plant
from cartctl.runtime.base import Controller
from cartctl.runtime.executor import SimulatedClock, TimingStats, check_count, check_period
from cartctl.runtime.loop import ControlLoop, LoopState, MemorySink, PerTick


class BackToBackExecutor:
    """Calls ``tick(k)`` back to back (tick k at ``k * period_s``) up to ``max_ticks``, and
    ``idle`` every ``idle_every`` ticks and at the end; ``ticks`` counts them."""

    def __init__(self, period_s: float, *, max_ticks: int, idle_every: int = 1000) -> None:
        self.period_s = check_period(period_s)
        self.max_ticks = check_count("max_ticks", max_ticks, 0)
        self.idle_every = check_count("idle_every", idle_every, 1)
        self.ticks = 0

    def run(
        self, tick: Callable[[int], bool], idle: Callable[[], None] | None = None
    ) -> TimingStats:
        """Call ``tick(k)`` until it returns False or ``max_ticks`` ran; an exception from it
        propagates (:meth:`stats` counts the ticks completed)."""
        self.ticks = 0
        every = self.idle_every
        for k in range(self.max_ticks):
            keep_going = tick(k)
            self.ticks = k + 1
            if idle is not None and self.ticks % every == 0:
                idle()
            if not keep_going:
                break
        if idle is not None and self.ticks % every:
            idle()
        return self.stats()

    def stats(self) -> TimingStats:
        """The ticks completed, with zero timing."""
        zeros = np.zeros(self.ticks)
        return TimingStats.from_samples(
            zeros, zeros, period_s=self.period_s,
            duration_s=max(self.ticks - 1, 0) * self.period_s,
        )  # fmt: skip


def run_in_memory(
    plant: Plant,
    controllers: Mapping[str, Controller],
    references: Mapping[str, PerTick],
    *,
    period_s: float,
    voltage_limit_v: float,
) -> tuple[dict[str, NDArray[np.float64]], LoopState]:
    """Run with a :class:`~cartctl.runtime.loop.MemorySink` (ending, like every run, with the
    zero-volt stop row): the trace columns and what happened (a plant fault in ``state.failure``)."""
    clock, memory = SimulatedClock(), MemorySink()
    loop = ControlLoop(plant, controllers, references, [memory], now_s=clock.now_s,
                       voltage_limit_v=voltage_limit_v, period_s=period_s)  # fmt: skip
    executor, loop_tick = BackToBackExecutor(period_s, max_ticks=loop.n_ticks), loop.tick
    try:
        loop.start()
        executor.run(lambda k: loop_tick(k, 0.0, 0.0, k * period_s), loop.idle)
    except PlantError as exc:
        loop.state.failure = str(exc)
    finally:
        loop.finish()
    return memory.arrays(), loop.state
