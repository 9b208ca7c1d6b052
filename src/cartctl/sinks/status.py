"""A live status line on the terminal during a real-time run: tick, reference, speed, voltage, misses.

A sink (see :mod:`cartctl.sinks.base`): ``write`` keeps the tick's row (one reference, no work) and
``idle``, which the loop calls after the tick's compute time is taken, rewrites one line on the
terminal every ``every_s`` seconds of run time (4 times a second by default), so it costs the
tick nothing. ``cartctl run`` adds it only when stderr is a terminal; the line is ended at
``close``, before the summary.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TextIO

__all__ = ["StatusLine"]


class StatusLine:
    """One terminal line, rewritten in place with the latest tick's figures.

    Parameters
    ----------
    stream : TextIO
        Where the line goes (a terminal: ``\\r`` moves back to its start).
    period_s : float
        The loop's tick (s): a tick is a deadline miss when its start error and compute time
        together pass it.
    every_s : float
        Run time between two refreshes (s).
    """

    def __init__(self, stream: TextIO, *, period_s: float, every_s: float = 0.25) -> None:
        self.stream = stream
        self.period_s = float(period_s)
        self.every_ticks = max(1, round(every_s / period_s))
        self._row: Sequence[float] | None = None
        self._index: dict[str, int] = {}
        self._misses = 0
        self._since = 0
        self._shown = False

    def open(self, columns: Sequence[str]) -> None:
        self._index = {name: i for i, name in enumerate(columns)}

    def write(self, row: Sequence[float]) -> None:
        self._row = row
        self._since += 1
        i, j = self._index.get("period_error_us"), self._index.get("compute_us")
        if i is not None and j is not None and row[i] + row[j] > self.period_s * 1e6:
            self._misses += 1

    def idle(self) -> None:
        """Rewrite the line when ``every_s`` of run time has passed since the last time."""
        if self._row is None or self._since < self.every_ticks:
            return
        self._since = 0
        self.stream.write("\r" + self.line() + "\x1b[K")  # then clear to the end of the line
        self.stream.flush()
        self._shown = True

    def line(self) -> str:
        """The status of the latest tick: time, tick, per motor r, y, u, and the misses so far."""
        row, at = self._row, self._index
        if row is None:
            return ""

        def value(name: str) -> float:
            return row[at[name]] if name in at else math.nan

        parts = [f"t {value('time_s'):7.2f} s", f"tick {int(value('tick')):>6}"]
        for m in ("a", "b"):
            if f"reference_{m}" in at:
                parts.append(
                    f"{m}: r {value(f'reference_{m}'):6.2f} y {value(f'speed_{m}'):6.2f} rad/s "
                    f"u {value(f'voltage_{m}'):6.2f} V"
                )
        parts.append(f"misses {self._misses}")
        return "  ".join(parts)

    def close(self) -> None:
        """End the line, so that what follows starts on a new one."""
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False
