"""The executor of the fast simulated loop: ticks back to back on simulated time.

``run --fast``, ``tune`` and the Python API run the real-time run's
:class:`~cartctl.runtime.loop.ControlLoop`, but nothing waits for a deadline: every tick starts
on its grid point (period error 0), takes no simulated time and cannot miss. So
:class:`BackToBackExecutor` only counts ticks and lets the sinks do their block work (``idle``)
every :attr:`~BackToBackExecutor.idle_every` ticks instead of after each: about a quarter of the
fast loop's time saved (``benchmarks/bench_run.py``). A tick that needs simulated time to pass
belongs on the periodic executor with a :class:`~cartctl.runtime.executor.SimulatedClock`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cartctl.runtime.executor import TimingStats, check_count, check_period


class BackToBackExecutor:
    """Calls ``tick(k)`` for k = 0, 1, ... back to back (tick k at ``k * period_s``) up to
    ``max_ticks``, and ``idle`` every ``idle_every`` ticks and at the end; ``ticks`` counts them.

    Examples
    --------
    >>> ex = BackToBackExecutor(0.01, max_ticks=3)
    >>> ex.run(lambda k: True).ticks
    3
    """

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
