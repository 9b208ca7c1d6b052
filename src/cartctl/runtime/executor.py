"""The loop's heartbeat: clocks, and the executors that call a tick function on their grid.

Time enters the runtime only through a :class:`Clock` (:class:`MonotonicClock`, or
:class:`SimulatedClock` for tests). :class:`PeriodicExecutor`, with ``t0`` the clock at ``run``:
tick k waits for grid point m's deadline ``t0 + m * period_s`` (computed, never accumulated);
its period error is start − deadline, its compute time end − start; it misses when it ends after
the next grid point. The next tick then starts at the first grid point not before the end, the
points passed over counted as skipped and the miss logged with its tick index (so ``grid_index``
may run ahead of k). The last tick is not checked for a miss.

:class:`CartClockedExecutor` starts tick k when the cart's k-th GPIO arrives. Its period error is
how much later that GPIO arrived than the run's earliest-arriving tick predicts (jitter, not the
constant 5.2 ms transmission); compute runs from the arrival to the command sent; a miss is a
tick after which older GPIOs were dropped to answer the freshest one.

Every executor runs a tick, its bookkeeping and ``idle`` inside :class:`cartctl.stopping.held`: a
stop signal that comes meanwhile is raised as the tick ends, never inside it.
"""

from __future__ import annotations

import logging
import math
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from cartctl.errors import InputError
from cartctl.measures.metrics import percentiles
from cartctl.plants.base import ClockedPlant
from cartctl.stopping import held

_log = logging.getLogger(__name__)

MISS_LOG_LIMIT = 20
"""Misses logged one by one per run; later ones are counted, and summed up at the end."""


@runtime_checkable
class Clock(Protocol):
    """A monotonic time source (s, arbitrary origin) that can wait for an absolute deadline."""

    def now_s(self) -> float: ...

    def wait_until(self, deadline_s: float) -> None: ...


class MonotonicClock:
    """:func:`time.perf_counter`; ``wait_until`` sleeps until ``spin_s`` (s) before the deadline,
    then busy-waits, absorbing the sleep's 50-100 µs wake-up latency."""

    def __init__(self, spin_s: float = 0.001) -> None:
        if not (math.isfinite(spin_s) and spin_s >= 0.0):
            raise InputError(f"spin_s must be a finite time >= 0 s, got {spin_s!r}")
        self.spin_s = float(spin_s)

    def now_s(self) -> float:
        return time.perf_counter()

    def wait_until(self, deadline_s: float) -> None:
        clock = time.perf_counter
        sleep_s = deadline_s - self.spin_s - clock()
        if sleep_s > 0.0:
            time.sleep(sleep_s)
        while clock() < deadline_s:
            pass


class SimulatedClock:
    """Simulated time (s), moved only by :meth:`wait_until` and :meth:`advance`."""

    def __init__(self, start_s: float = 0.0) -> None:
        if not math.isfinite(start_s):
            raise InputError(f"start_s must be a finite time in s, got {start_s!r}")
        self._now_s = float(start_s)

    def now_s(self) -> float:
        return self._now_s

    def wait_until(self, deadline_s: float) -> None:
        if deadline_s > self._now_s:
            self._now_s = deadline_s

    def advance(self, dt_s: float) -> None:
        """Let ``dt_s`` seconds pass (>= 0, finite)."""
        if not (math.isfinite(dt_s) and dt_s >= 0.0):
            raise InputError(
                f"a simulated clock only moves forward: dt_s must be >= 0 s, got {dt_s!r}"
            )
        self._now_s += dt_s


def check_period(period_s: float) -> float:
    """``period_s`` as a float, or InputError unless it is a finite time > 0 s."""
    if not (isinstance(period_s, int | float) and math.isfinite(period_s) and period_s > 0.0):
        raise InputError(f"period_s must be a finite time > 0 s, got {period_s!r}")
    return float(period_s)


def check_count(name: str, value: int, minimum: int) -> int:
    """``value``, or InputError unless it is an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return value


@dataclass(frozen=True)
class TimingStats:
    """One run's timing (module docstring): ``duration_s`` from the first deadline to the end of
    the last tick; period error and compute time (µs): median, 99th percentile, maximum (None: no
    tick ran)."""

    period_s: float
    ticks: int
    duration_s: float
    misses: int
    skipped_deadlines: int
    miss_ticks: tuple[int, ...]
    period_error_us_p50: float | None
    period_error_us_p99: float | None
    period_error_us_max: float | None
    compute_us_p50: float | None
    compute_us_p99: float | None
    compute_us_max: float | None

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
        pe = np.asarray(period_error_us, dtype=np.float64)
        cu = np.asarray(compute_us, dtype=np.float64)
        if pe.shape != cu.shape or pe.ndim != 1:
            raise InputError(
                f"period_error_us and compute_us must be 1-D and equally long, got shapes "
                f"{pe.shape} and {cu.shape}"
            )
        figures = (*percentiles(pe).values(), *percentiles(cu).values())
        misses = tuple(int(k) for k in miss_ticks)
        head = (float(period_s), int(pe.size), float(duration_s), len(misses))
        return cls(*head, int(skipped_deadlines), misses, *figures)

    def to_dict(self) -> dict[str, Any]:
        """The timing part of ``run --json`` (docs/architecture.md), plus skipped deadlines."""

        def nums(name: str) -> dict[str, float | None]:
            return {k: getattr(self, f"{name}_{k}") for k in ("p50", "p99", "max")}

        return {
            "ticks": self.ticks,
            "duration_s": self.duration_s,
            "deadline_misses": self.misses,
            "skipped_deadlines": self.skipped_deadlines,
            "miss_ticks": list(self.miss_ticks),
            "period_error_us": nums("period_error_us"),
            "compute_us": nums("compute_us"),
        }


class _Recorder:
    """A run's per-tick period errors and compute times (µs), its misses and its span."""

    period_s: float

    def _clear(self) -> None:
        self._period_error_us = array("d")
        self._compute_us = array("d")
        self._miss_ticks: list[int] = []
        self._skipped = 0
        self.t0_s = self._end_s = math.nan

    def _skipped_deadlines(self) -> int:
        return self._skipped

    def stats(self) -> TimingStats:
        """The current or last run's, over the ticks completed so far."""
        duration = 0.0 if math.isnan(self._end_s) else self._end_s - self.t0_s
        return TimingStats.from_samples(
            np.frombuffer(self._period_error_us, dtype=np.float64),
            np.frombuffer(self._compute_us, dtype=np.float64),
            period_s=self.period_s, duration_s=duration,
            miss_ticks=tuple(self._miss_ticks), skipped_deadlines=self._skipped_deadlines(),
        )  # fmt: skip


class PeriodicExecutor(_Recorder):
    """Runs a tick function every ``period_s`` (s) on absolute deadlines of ``clock``, at most
    ``max_ticks`` times; while a tick runs, ``tick_index`` (k), ``grid_index`` (m), ``deadline_s``,
    ``start_s`` and ``period_error_us`` describe it."""

    def __init__(self, period_s: float, clock: Clock, *, max_ticks: int | None = None) -> None:
        self.period_s = check_period(period_s)
        self.max_ticks = None if max_ticks is None else check_count("max_ticks", max_ticks, 0)
        if not isinstance(clock, Clock):
            raise InputError(
                f"clock must provide now_s() and wait_until(deadline_s), got {type(clock).__name__}"
            )
        self.clock = clock
        self.deadline_s = self.start_s = math.nan
        self.tick_index = self.grid_index = 0
        self.period_error_us = 0.0
        self._clear()

    def run(
        self, tick: Callable[[int], bool], idle: Callable[[], None] | None = None
    ) -> TimingStats:
        """Call ``tick(k)`` on a new deadline grid until it returns False or ``max_ticks`` ran (an
        exception propagates); ``idle`` runs after each tick's compute time is taken, before the
        wait (past the deadline, it shows as the next period error)."""
        self._clear()
        now, wait_until = self.clock.now_s, self.clock.wait_until
        period, limit = self.period_s, self.max_ticks
        err_append, comp_append = self._period_error_us.append, self._compute_us.append
        t0 = self.t0_s = now()
        k = m = 0
        try:
            while limit is None or k < limit:
                deadline = t0 + m * period
                wait_until(deadline)  # a stop signal ends the run here, or as its tick ends
                with held():
                    start = now()
                    self.tick_index, self.grid_index = k, m
                    self.deadline_s, self.start_s = deadline, start
                    self.period_error_us = err_us = (start - deadline) * 1e6
                    keep_going = tick(k)
                    end = self._end_s = now()
                    err_append(err_us)
                    comp_append((end - start) * 1e6)
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
                    len(self._miss_ticks), k, self._skipped, period,
                )  # fmt: skip
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
                k, m_next - 1, (end_s - (t0 + m_next * period)) * 1e6, skipped, m,
                "; further misses are only counted" if n == MISS_LOG_LIMIT else "",
            )  # fmt: skip
        return m


class BackToBackExecutor:
    """The fast simulated loop's executor: ``tick(k)`` back to back (at ``k * period_s``, period
    error 0) up to ``max_ticks``, and ``idle`` every ``idle_every`` ticks and at the end."""

    def __init__(self, period_s: float, *, max_ticks: int, idle_every: int = 1000) -> None:
        self.period_s = check_period(period_s)
        self.max_ticks = check_count("max_ticks", max_ticks, 0)
        self.idle_every = check_count("idle_every", idle_every, 1)
        self.ticks = 0

    def run(
        self, tick: Callable[[int], bool], idle: Callable[[], None] | None = None
    ) -> TimingStats:
        """Call ``tick(k)`` until it returns False or ``max_ticks`` ran."""
        self.ticks = 0
        every = self.idle_every
        for k in range(self.max_ticks):
            with held():
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
        zeros, duration = np.zeros(self.ticks), max(self.ticks - 1, 0) * self.period_s
        return TimingStats.from_samples(zeros, zeros, period_s=self.period_s, duration_s=duration)


class CartClockedExecutor(_Recorder):
    """Runs ``tick(k)`` once per cart tick until it returns False or ``max_ticks`` ran;
    ``compute_us`` gives the compute time of the tick just run (µs), ``now_s`` the clock the plant
    stamps arrivals with."""

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
        self._clear()

    def _skipped_deadlines(self) -> int:
        return int(getattr(self.plant, "skipped_ticks", 0))

    def run(self, tick: Callable[[int], bool]) -> TimingStats:
        plant, period = self.plant, self.period_s
        anchor = math.inf
        self.t0_s = plant.arrival_s
        for k in range(self.max_ticks):
            arrival = plant.arrival_s
            base = arrival - plant.tick_index * period
            anchor = min(anchor, base)
            self.period_error_us = (base - anchor) * 1e6
            self.start_s = arrival
            self.time_s = plant.tick_index * period
            with held():  # the wait for the cart's next frame included: 10 ms, or a fault
                skipped_before = self._skipped_deadlines()
                keep_going = tick(k)
                self._end_s = self.now_s()
                self._period_error_us.append(self.period_error_us)
                self._compute_us.append(self.compute_us())
                if self._skipped_deadlines() > skipped_before:
                    self._miss_ticks.append(k)
                if not keep_going:
                    break
        return self.stats()
