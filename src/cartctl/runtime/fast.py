"""The loop of ``cartctl run --fast`` kept in memory, for tune and the Python API: the same
:class:`~cartctl.runtime.loop.ControlLoop` on a simulated clock, ticks back to back, a
:class:`~cartctl.runtime.loop.MemorySink` instead of files, and the zero-volt stop row at the end.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import PlantError
from cartctl.plants.base import Plant
from cartctl.runtime.back_to_back import BackToBackExecutor
from cartctl.runtime.base import Controller
from cartctl.runtime.executor import SimulatedClock
from cartctl.runtime.loop import ControlLoop, LoopState, MemorySink, PerTick


def run_in_memory(
    plant: Plant,
    controllers: Mapping[str, Controller],
    references: Mapping[str, PerTick],
    *,
    period_s: float,
    voltage_limit_v: float,
) -> tuple[dict[str, NDArray[np.float64]], LoopState]:
    """The trace columns and what happened (a plant fault ends the run, in ``state.failure``)."""
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
