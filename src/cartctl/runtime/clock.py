"""Clocks for the periodic executor: time enters the runtime only through a :class:`Clock`.

The real-time loop runs on :class:`MonotonicClock`; tests run the same executor on
:class:`SimulatedClock`, which never sleeps.
"""

from __future__ import annotations

import math
import time
from typing import Protocol, runtime_checkable

from cartctl.errors import InputError


@runtime_checkable
class Clock(Protocol):
    """A monotonic time source (s, arbitrary origin) that can wait for an absolute deadline."""

    def now_s(self) -> float: ...

    def wait_until(self, deadline_s: float) -> None:
        """Return at or after ``deadline_s``; at once if it has passed."""
        ...


class MonotonicClock:
    """:func:`time.perf_counter` (``CLOCK_MONOTONIC`` on Linux), with a sleep-then-spin wait.

    ``wait_until`` sleeps until ``spin_s`` (s, >= 0) before the deadline, then busy-waits for the
    rest: the spin absorbs the sleep's wake-up latency (50-100 µs, outliers of milliseconds on a
    busy machine), at the price of up to ``spin_s`` of a core per wait (10 % at 1 ms per 10 ms).
    A thread woken too late still starts late: that is what SCHED_FIFO
    (:mod:`cartctl.runtime.realtime`) is for. ``spin_s = 0`` is a plain sleep.
    """

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
    """Simulated time (s), moved only by :meth:`wait_until` (straight to the deadline) and
    :meth:`advance` (a test's slow work, a simulated plant's own latency)."""

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
