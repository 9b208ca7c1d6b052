"""A live status line on the terminal during a real-time run: tick, reference, speed, voltage, misses."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TextIO


class StatusLine:
    """A sink that rewrites one terminal line every ``every_s`` of run time, from ``idle`` (so the
    tick pays nothing); a tick is a miss when its start error and compute time pass ``period_s``."""

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
        if self._row is None or self._since < self.every_ticks:
            return
        self._since = 0
        self.stream.write("\r" + self.line() + "\x1b[K")  # then clear to the end of the line
        self.stream.flush()
        self._shown = True

    def line(self) -> str:
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
        if self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = False
