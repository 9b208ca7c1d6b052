"""The loop of ``cartctl run --fast`` kept in memory: for tune and the Python API.

The same :class:`~cartctl.runtime.loop.ControlLoop` on a :class:`~cartctl.runtime.clock.SimulatedClock`
and a :class:`~cartctl.runtime.back_to_back.BackToBackExecutor` (ticks back to back), with a
:class:`~cartctl.runtime.loop.MemorySink` instead of files: as fast as the CPU allows, and
ending, like every run, with the zero-volt stop row.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import PlantError
from cartctl.plants.base import Plant
from cartctl.runtime.back_to_back import BackToBackExecutor
from cartctl.runtime.base import Controller
from cartctl.runtime.clock import SimulatedClock
from cartctl.runtime.loop import ControlLoop, LoopState, MemorySink, PerTick


def run_in_memory(
    plant: Plant,
    controllers: Mapping[str, Controller],
    references: Mapping[str, PerTick],
    *,
    period_s: float,
    voltage_limit_v: float,
) -> tuple[dict[str, NDArray[np.float64]], LoopState]:
    """Run the loop on a simulated clock; returns the trace columns and what happened.

    ``plant``, ``controllers`` and ``references`` (rad/s per tick) are as for
    :class:`~cartctl.runtime.loop.ControlLoop`; ``period_s`` is the tick (s), ``voltage_limit_v``
    the clamp (V). A plant fault ends the run early and is in ``state.failure``.
    """
    clock, memory = SimulatedClock(), MemorySink()
    loop = ControlLoop(plant, controllers, references, [memory], now_s=clock.now_s,
                       voltage_limit_v=voltage_limit_v, period_s=period_s)  # fmt: skip
    executor = BackToBackExecutor(period_s, max_ticks=loop.n_ticks)
    loop_tick = loop.tick
    try:
        loop.start()

        def tick(k: int) -> bool:
            return loop_tick(k, 0.0, 0.0, k * period_s)

        executor.run(tick, loop.idle)
    except PlantError as exc:
        loop.state.failure = str(exc)
    finally:
        loop.finish()
    return memory.arrays(), loop.state
