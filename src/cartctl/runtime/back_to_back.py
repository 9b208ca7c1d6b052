"""The executor of the fast simulated loop: ticks back to back on simulated time.

``cartctl run --fast``, ``tune`` and the Python API run the same
:class:`~cartctl.runtime.loop.ControlLoop` as a real-time run, but nothing in them waits for a
deadline, so none of the real-time bookkeeping of
:class:`~cartctl.runtime.executor.PeriodicExecutor` applies: every tick starts on its grid point
(period error 0), takes no simulated time (compute 0) and cannot miss. :class:`BackToBackExecutor`
therefore only counts ticks, calls the tick function, and lets the sinks do their block work
(``idle``) every :attr:`~BackToBackExecutor.idle_every` ticks instead of after every tick. That is
about a quarter of the fast loop's time saved against the periodic executor on a simulated clock
(``benchmarks/bench_run.py`` prints the figures).

A tick that needs simulated time to pass (a test of a slow tick, a miss) belongs on the periodic
executor with a :class:`~cartctl.runtime.clock.SimulatedClock`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cartctl.errors import InputError
from cartctl.runtime.executor import TimingStats


class BackToBackExecutor:
    """Calls ``tick(k)`` for k = 0, 1, ... back to back: simulated time, no deadlines.

    Parameters
    ----------
    period_s : float
        Tick period (s), > 0: tick k sits at ``k * period_s`` on the time axis.
    max_ticks : int
        Stop after this many ticks (>= 0).
    idle_every : int, default 1000
        Ticks between calls of ``idle`` (and once more at the end of the run).

    Attributes
    ----------
    ticks : int
        Ticks completed by the current or last run.

    Examples
    --------
    >>> ex = BackToBackExecutor(0.01, max_ticks=3)
    >>> ex.run(lambda k: True).ticks
    3
    """

    def __init__(self, period_s: float, *, max_ticks: int, idle_every: int = 1000) -> None:
        if not (isinstance(period_s, int | float) and np.isfinite(period_s) and period_s > 0.0):
            raise InputError(f"period_s must be a finite time > 0 s, got {period_s!r}")
        if isinstance(max_ticks, bool) or not isinstance(max_ticks, int) or max_ticks < 0:
            raise InputError(f"max_ticks must be an integer >= 0, got {max_ticks!r}")
        if isinstance(idle_every, bool) or not isinstance(idle_every, int) or idle_every < 1:
            raise InputError(f"idle_every must be an integer >= 1, got {idle_every!r}")
        self.period_s = float(period_s)
        self.max_ticks = max_ticks
        self.idle_every = idle_every
        self.ticks = 0

    def run(
        self, tick: Callable[[int], bool], idle: Callable[[], None] | None = None
    ) -> TimingStats:
        """Call ``tick(k)`` until it returns False or ``max_ticks`` ran.

        Parameters
        ----------
        tick : callable
            ``tick(k) -> bool``; a false return value stops the run after this tick. An exception
            from it ends the run and propagates; :meth:`stats` still counts the ticks completed.
        idle : callable, optional
            Called after every ``idle_every``-th tick and after the last one.

        Returns
        -------
        TimingStats
            Zero period errors and compute times, no misses, one entry per tick.
        """
        self.ticks = 0
        every = self.idle_every
        k = 0
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
        """Statistics of the current or last run: the ticks completed, zero timing."""
        zeros = np.zeros(self.ticks)
        return TimingStats.from_samples(
            zeros, zeros, period_s=self.period_s,
            duration_s=max(self.ticks - 1, 0) * self.period_s,
        )  # fmt: skip
