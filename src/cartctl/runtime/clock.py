"""Clocks for the periodic executor: the real monotonic clock and a simulated one.

The runtime is the shell around the pure per-tick core, and time enters it only through a
:class:`Clock`. The real-time loop runs on :class:`MonotonicClock`; the fast simulated loop and
the tests run the same executor on :class:`SimulatedClock`, which never sleeps.
"""

from __future__ import annotations

import math
import time
from typing import Protocol, runtime_checkable

from cartctl.errors import InputError


@runtime_checkable
class Clock(Protocol):
    """A monotonic time source that can wait for an absolute deadline (seconds)."""

    def now_s(self) -> float:
        """Current time (s), monotonic; the origin is arbitrary."""
        ...

    def wait_until(self, deadline_s: float) -> None:
        """Return at or after ``deadline_s`` (s, on this clock); at once if it has passed."""
        ...


class MonotonicClock:
    """The system's monotonic clock, with a hybrid sleep-then-spin wait.

    ``now_s`` is :func:`time.perf_counter` (``CLOCK_MONOTONIC`` on Linux: not affected by
    wall-clock changes, nanosecond resolution). ``wait_until`` sleeps until ``spin_s`` before the
    deadline, then busy-waits on the clock for the rest. The sleep lets the OS run other work;
    the spin absorbs the sleep's wake-up latency (typically 50-100 µs, with outliers of
    milliseconds on a busy machine), so the wait returns within a few microseconds of the
    deadline as long as the thread wakes up before it. The price is up to ``spin_s`` of one core's
    time per wait (10 % of a core at 1 ms per 10 ms period). Without real-time scheduling a
    thread that is not woken in time still starts late: the spin cannot help there, which is
    what SCHED_FIFO (see :mod:`cartctl.runtime.realtime`) is for.

    Parameters
    ----------
    spin_s : float, default 0.001
        Length of the busy-wait before each deadline (s), >= 0. 0 gives a plain sleep to an
        absolute deadline.

    Raises
    ------
    InputError
        If ``spin_s`` is negative or not finite.
    """

    def __init__(self, spin_s: float = 0.001) -> None:
        if not (math.isfinite(spin_s) and spin_s >= 0.0):
            raise InputError(f"spin_s must be a finite time >= 0 s, got {spin_s!r}")
        self.spin_s = float(spin_s)

    def now_s(self) -> float:
        """Current time (s) of the monotonic clock (arbitrary origin)."""
        return time.perf_counter()

    def wait_until(self, deadline_s: float) -> None:
        """Sleep until ``spin_s`` before ``deadline_s`` (s), then spin until it has passed."""
        clock = time.perf_counter
        sleep_s = deadline_s - self.spin_s - clock()
        if sleep_s > 0.0:
            time.sleep(sleep_s)
        while clock() < deadline_s:
            pass


class SimulatedClock:
    """Simulated time: waiting jumps straight to the deadline, so nothing ever sleeps.

    Time only moves in :meth:`wait_until` and :meth:`advance`. Ticks therefore take zero time
    unless the tick itself calls :meth:`advance` (a test simulating slow work, or a simulated
    plant modelling its own latency).

    Parameters
    ----------
    start_s : float, default 0.0
        Initial time (s).
    """

    def __init__(self, start_s: float = 0.0) -> None:
        if not math.isfinite(start_s):
            raise InputError(f"start_s must be a finite time in s, got {start_s!r}")
        self._now_s = float(start_s)

    def now_s(self) -> float:
        """Current simulated time (s)."""
        return self._now_s

    def wait_until(self, deadline_s: float) -> None:
        """Move the time forward to ``deadline_s`` (s); no change if it has already passed."""
        if deadline_s > self._now_s:
            self._now_s = deadline_s

    def advance(self, dt_s: float) -> None:
        """Let ``dt_s`` seconds pass (s, >= 0), as work that takes that long would.

        Raises
        ------
        InputError
            If ``dt_s`` is negative or not finite.
        """
        if not (math.isfinite(dt_s) and dt_s >= 0.0):
            raise InputError(
                f"a simulated clock only moves forward: dt_s must be >= 0 s, got {dt_s!r}"
            )
        self._now_s += dt_s
