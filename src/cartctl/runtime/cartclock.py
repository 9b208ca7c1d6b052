"""The loop on the cart's clock: tick k starts when the cart's k-th GPIO arrives.

Against a serial cart the cart ticks every 10 ms and sends one GPIO per tick, and the host answers
each, so the timing figures differ slightly from :class:`~cartctl.runtime.executor.PeriodicExecutor`'s:
the **period error** of tick k is how much later its GPIO arrived than the earliest-arriving tick
of the run predicts (the line's and the host's jitter, not the constant 5.2 ms transmission);
**compute** runs from the GPIO's arrival to the command sent; a **miss** is a tick after which the
host had fallen behind, so older GPIOs were dropped to answer the freshest one.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable

import numpy as np

from cartctl.plants.base import ClockedPlant
from cartctl.runtime.executor import TimingStats


class CartClockedExecutor:
    """Runs ``tick(k)`` once per cart tick until it returns False or ``max_ticks`` ran.

    ``plant``'s latest measurement must have arrived (the loop's ``start`` resets it);
    ``compute_us`` gives the loop's compute time of the tick just run (µs); ``now_s`` is the host
    clock the plant stamps arrivals with (``time.perf_counter``).
    """

    def __init__(
        self,
        plant: ClockedPlant,
        *,
        max_ticks: int,
        compute_us: Callable[[], float],
        now_s: Callable[[], float],
    ) -> None:
        self.plant = plant
        self.period_s = plant.period_s
        self.max_ticks = int(max_ticks)
        self.compute_us = compute_us
        self.now_s = now_s
        self.period_error_us = self.start_s = self.time_s = 0.0
        self._errors_us = array("d")
        self._compute = array("d")
        self._misses: list[int] = []
        self._t0 = self._end = math.nan

    def run(self, tick: Callable[[int], bool]) -> TimingStats:
        """Run the ticks; an exception from ``tick`` propagates (:meth:`stats` has the ticks done)."""
        plant, period = self.plant, self.period_s
        anchor = math.inf
        self._t0 = plant.arrival_s
        for k in range(self.max_ticks):
            arrival = plant.arrival_s
            base = arrival - plant.tick_index * period
            anchor = min(anchor, base)
            self.period_error_us = (base - anchor) * 1e6
            self.start_s = arrival
            self.time_s = plant.tick_index * period
            skipped_before = getattr(plant, "skipped_ticks", 0)
            keep_going = tick(k)
            self._end = self.now_s()
            self._errors_us.append(self.period_error_us)
            self._compute.append(self.compute_us())
            if getattr(plant, "skipped_ticks", 0) > skipped_before:
                self._misses.append(k)
            if not keep_going:
                break
        return self.stats()

    def stats(self) -> TimingStats:
        """Statistics over the ticks completed so far."""
        duration = 0.0 if math.isnan(self._end) else self._end - self._t0
        return TimingStats.from_samples(
            np.frombuffer(self._errors_us, dtype=np.float64),
            np.frombuffer(self._compute, dtype=np.float64),
            period_s=self.period_s,
            duration_s=duration,
            miss_ticks=tuple(self._misses),
            skipped_deadlines=getattr(self.plant, "skipped_ticks", 0),
        )
