"""The periodic executor: calls a tick function on a fixed grid of absolute deadlines.

The runtime is the shell around the pure per-tick core; this module is its heartbeat. The same
:class:`PeriodicExecutor` runs the real-time loop on a :class:`~cartctl.runtime.clock.MonotonicClock`
and the fast simulated loop on a :class:`~cartctl.runtime.clock.SimulatedClock`, so it keeps its
per-tick work to a few attribute stores and two appends of a float.

Contract of :meth:`PeriodicExecutor.run`, with ``t0`` the clock's time when ``run`` starts::

    grid point m       deadline_m = t0 + m * period_s        (computed, never accumulated: no drift)
    tick k             waits for its deadline, then calls tick(k); k = 0, 1, 2, ... counts ticks
    period error       start_k - deadline                    (>= 0 on a real clock; 0 on a simulated one)
    compute time       end_k - start_k                        (on the same clock)
    deadline miss      end_k > the next grid point            (the tick overran its period)

After a miss the next tick starts at the first grid point not before ``end_k``; the grid points
passed over are counted as skipped deadlines, the miss is logged (``logging``, logger
``cartctl.runtime.executor``) and recorded in the statistics with its tick index. Without misses
tick k starts at grid point k; after skipped deadlines the grid index runs ahead of k, and
:attr:`PeriodicExecutor.grid_index` says where tick k sits in time (``grid_index * period_s``
after ``t0``). The last tick is not checked for a miss: no further deadline is waited for.
"""

from __future__ import annotations

import logging
import math
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from cartctl.errors import InputError
from cartctl.runtime.clock import Clock

_log = logging.getLogger(__name__)

#: Misses logged one by one per run; later ones are counted, and summed up at the end of the run.
MISS_LOG_LIMIT = 20


@dataclass(frozen=True)
class TimingStats:
    """Timing of one run of the executor.

    Percentiles are NaN when no tick ran (``to_dict`` gives null for them).

    Attributes
    ----------
    period_s : float
        The period (s).
    ticks : int
        Ticks that completed (tick function returned).
    duration_s : float
        From the first deadline to the end of the last tick (s, on the executor's clock).
    misses : int
        Ticks that ended after the next deadline.
    skipped_deadlines : int
        Grid points passed over after misses (no tick started at them). At least ``misses``.
    miss_ticks : tuple of int
        Tick index k of every miss.
    period_error_us_p50, period_error_us_p99, period_error_us_max : float
        Start of each tick minus its deadline (µs): median, 99th percentile, maximum.
    compute_us_p50, compute_us_p99, compute_us_max : float
        Duration of each tick function call (µs): median, 99th percentile, maximum.
    """

    period_s: float
    ticks: int
    duration_s: float
    misses: int
    skipped_deadlines: int
    miss_ticks: tuple[int, ...]
    period_error_us_p50: float
    period_error_us_p99: float
    period_error_us_max: float
    compute_us_p50: float
    compute_us_p99: float
    compute_us_max: float

    @classmethod
    def from_samples(
        cls,
        period_error_us: np.ndarray,
        compute_us: np.ndarray,
        *,
        period_s: float,
        duration_s: float = 0.0,
        miss_ticks: tuple[int, ...] = (),
        skipped_deadlines: int = 0,
    ) -> TimingStats:
        """Statistics from per-tick samples.

        Parameters
        ----------
        period_error_us, compute_us : ndarray, shape (n,)
            Per-tick period error and compute time (µs), one entry per completed tick.
        period_s : float
            The period (s).
        duration_s : float, optional
            Duration of the run (s).
        miss_ticks : tuple of int, optional
            Tick indices of the misses.
        skipped_deadlines : int, optional
            Grid points passed over.
        """
        pe = np.asarray(period_error_us, dtype=np.float64)
        cu = np.asarray(compute_us, dtype=np.float64)
        if pe.shape != cu.shape or pe.ndim != 1:
            raise InputError(
                f"period_error_us and compute_us must be 1-D and equally long, got shapes "
                f"{pe.shape} and {cu.shape}"
            )
        if pe.size:
            pe50, pe99 = np.percentile(pe, [50.0, 99.0])
            cu50, cu99 = np.percentile(cu, [50.0, 99.0])
            pemax, cumax = pe.max(), cu.max()
        else:
            pe50 = pe99 = pemax = cu50 = cu99 = cumax = math.nan
        return cls(
            period_s=float(period_s),
            ticks=int(pe.size),
            duration_s=float(duration_s),
            misses=len(miss_ticks),
            skipped_deadlines=int(skipped_deadlines),
            miss_ticks=tuple(int(k) for k in miss_ticks),
            period_error_us_p50=float(pe50),
            period_error_us_p99=float(pe99),
            period_error_us_max=float(pemax),
            compute_us_p50=float(cu50),
            compute_us_p99=float(cu99),
            compute_us_max=float(cumax),
        )

    def to_dict(self) -> dict[str, Any]:
        """The timing part of ``run --json`` (docs/architecture.md), plus skipped deadlines.

        Returns
        -------
        dict
            ``{"ticks", "duration_s", "deadline_misses", "skipped_deadlines", "miss_ticks",
            "period_error_us": {"p50", "p99", "max"}, "compute_us": {"p50", "p99", "max"}}``;
            times in µs except ``duration_s`` (s); null for percentiles of an empty run.
        """

        def num(x: float) -> float | None:
            return None if math.isnan(x) else x

        return {
            "ticks": self.ticks,
            "duration_s": self.duration_s,
            "deadline_misses": self.misses,
            "skipped_deadlines": self.skipped_deadlines,
            "miss_ticks": list(self.miss_ticks),
            "period_error_us": {
                "p50": num(self.period_error_us_p50),
                "p99": num(self.period_error_us_p99),
                "max": num(self.period_error_us_max),
            },
            "compute_us": {
                "p50": num(self.compute_us_p50),
                "p99": num(self.compute_us_p99),
                "max": num(self.compute_us_max),
            },
        }


class PeriodicExecutor:
    """Runs a tick function every ``period_s`` on absolute deadlines of an injected clock.

    See the module docstring for the timing contract. While a tick runs, the executor's
    attributes describe it, so the tick function can log its own timing:

    - ``tick_index`` (k), ``grid_index`` (m, the grid point it was started for),
    - ``deadline_s`` and ``start_s`` (s, on the clock), ``period_error_us`` (µs),
    - ``last_compute_us``: compute time of the previous tick (µs; 0 before the second tick).

    Parameters
    ----------
    period_s : float
        Tick period (s), > 0.
    clock : Clock
        Time source and waiter: ``MonotonicClock`` for real time, ``SimulatedClock`` for simulation.
    max_ticks : int, optional
        Stop after this many ticks (>= 0). None: run until the tick function returns False.

    Raises
    ------
    InputError
        For a period that is not a positive finite time, a negative ``max_ticks``, or a clock
        without ``now_s`` and ``wait_until``.

    Examples
    --------
    >>> from cartctl.runtime.clock import SimulatedClock
    >>> ex = PeriodicExecutor(0.01, SimulatedClock(), max_ticks=3)
    >>> ex.run(lambda k: True).ticks
    3
    """

    def __init__(self, period_s: float, clock: Clock, *, max_ticks: int | None = None) -> None:
        if not (isinstance(period_s, int | float) and math.isfinite(period_s) and period_s > 0.0):
            raise InputError(f"period_s must be a finite time > 0 s, got {period_s!r}")
        if max_ticks is not None and (
            isinstance(max_ticks, bool) or not isinstance(max_ticks, int) or max_ticks < 0
        ):
            raise InputError(f"max_ticks must be None or an integer >= 0, got {max_ticks!r}")
        if not isinstance(clock, Clock):
            raise InputError(
                f"clock must provide now_s() and wait_until(deadline_s), got {type(clock).__name__}"
            )
        self.period_s = float(period_s)
        self.clock = clock
        self.max_ticks = max_ticks
        self.t0_s = math.nan
        self.tick_index = 0
        self.grid_index = 0
        self.deadline_s = math.nan
        self.start_s = math.nan
        self.period_error_us = 0.0
        self.last_compute_us = 0.0
        self._reset()

    def _reset(self) -> None:
        self._period_error_s = array("d")
        self._compute_s = array("d")
        self._miss_ticks: list[int] = []
        self._skipped = 0
        self._end_s = math.nan

    def run(
        self, tick: Callable[[int], bool], idle: Callable[[], None] | None = None
    ) -> TimingStats:
        """Call ``tick(k)`` on the deadline grid until it returns False or ``max_ticks`` ran.

        Parameters
        ----------
        tick : callable
            ``tick(k) -> bool`` with k the tick index (0, 1, ...); a false return value stops
            the run after this tick. An exception from it ends the run and propagates;
            :meth:`stats` still gives the ticks completed so far.
        idle : callable, optional
            Called after each tick, once its compute time is taken, before the wait for the next
            deadline: work that must not count as the tick's (it shows as the next tick's period
            error if it runs past the deadline).

        Returns
        -------
        TimingStats
            The statistics of this run (each call of ``run`` starts afresh, on a new grid).
        """
        self._reset()
        clock = self.clock
        now = clock.now_s
        wait_until = clock.wait_until
        period = self.period_s
        limit = self.max_ticks
        err_append = self._period_error_s.append
        comp_append = self._compute_s.append
        t0 = now()
        self.t0_s = t0
        self.last_compute_us = 0.0
        k = 0
        m = 0
        try:
            while limit is None or k < limit:
                deadline = t0 + m * period
                wait_until(deadline)
                start = now()
                err = start - deadline
                self.tick_index = k
                self.grid_index = m
                self.deadline_s = deadline
                self.start_s = start
                self.period_error_us = err * 1e6
                keep_going = tick(k)
                end = now()
                self._end_s = end
                err_append(err)
                comp_append(end - start)
                self.last_compute_us = (end - start) * 1e6
                if idle is not None:
                    idle()
                k += 1
                if not keep_going or k == limit:  # the last tick: no next deadline to check
                    break
                m += 1
                if end > t0 + m * period:
                    m = self._realign(k - 1, m, end)
        finally:
            if self._miss_ticks:
                _log.warning(
                    "%d deadline misses in %d ticks (%d deadlines skipped) at period %.6g s",
                    len(self._miss_ticks),
                    k,
                    self._skipped,
                    period,
                )
        return self.stats()

    def _realign(self, k: int, m_next: int, end_s: float) -> int:
        """Record the miss of tick k and return the first grid index at or after ``end_s``."""
        t0, period = self.t0_s, self.period_s
        m = max(m_next + 1, math.ceil((end_s - t0) / period))
        while t0 + m * period < end_s:  # guard against rounding in the division
            m += 1
        skipped = m - m_next
        self._skipped += skipped
        self._miss_ticks.append(k)
        n = len(self._miss_ticks)
        if n <= MISS_LOG_LIMIT:
            _log.warning(
                "deadline miss: tick %d (grid point %d) ended %.1f µs after the next deadline; "
                "%d deadline(s) skipped, next tick at grid point %d%s",
                k,
                m_next - 1,
                (end_s - (t0 + m_next * period)) * 1e6,
                skipped,
                m,
                "; further misses are only counted" if n == MISS_LOG_LIMIT else "",
            )
        return m

    def stats(self) -> TimingStats:
        """Statistics of the current or last run, over the ticks completed so far."""
        pe = np.frombuffer(self._period_error_s, dtype=np.float64) * 1e6
        cu = np.frombuffer(self._compute_s, dtype=np.float64) * 1e6
        duration = 0.0 if math.isnan(self._end_s) else self._end_s - self.t0_s
        return TimingStats.from_samples(
            pe,
            cu,
            period_s=self.period_s,
            duration_s=duration,
            miss_ticks=tuple(self._miss_ticks),
            skipped_deadlines=self._skipped,
        )
