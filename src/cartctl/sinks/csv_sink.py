"""The CSV trace sink: contract 1 plus the closed-loop columns, flushed at least once a second.

Each row is formatted as it comes (a few µs, the same every tick) and the lines are written in
blocks of ``flush_every`` ticks (default 50: twice a second at 10 ms), each block followed by a
flush, so a crash loses at most the last block. Writing happens in the loop's thread after the
tick's command has gone out (a writer thread would compete for the GIL and add wake-up jitter).
Formatting a whole block at its flush instead would put 50 rows' formatting, some 300 µs, into
every 50th tick: 2 % of the ticks, the loop's 99th percentile.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TextIO


class CsvSink:
    """Writes the loop's rows to a CSV file (``str`` of each value: shortest exact floats, whole ticks).

    Parameters
    ----------
    path : str or Path
        The trace file; parent folders are created.
    flush_every : int
        Rows per written block (ticks).
    """

    def __init__(self, path: str | Path, *, flush_every: int = 50) -> None:
        self.path = Path(path)
        self.flush_every = max(1, int(flush_every))
        self._file: TextIO | None = None
        self._lines: list[str] = []
        self.rows_written = 0

    def open(self, columns: Sequence[str]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("w", encoding="utf-8", newline="")
        self._file.write(",".join(columns) + "\n")
        self._file.flush()

    def write(self, row: Sequence[float]) -> None:
        lines = self._lines
        lines.append(",".join(map(str, row)))  # str: exact for floats (numpy ones too), whole ticks
        if len(lines) >= self.flush_every:
            self._flush()

    def _flush(self) -> None:
        if self._file is None or not self._lines:
            return
        self._file.write("\n".join(self._lines) + "\n")
        self._file.flush()
        self.rows_written += len(self._lines)
        self._lines = []

    def close(self) -> None:
        if self._file is None:
            return
        try:
            self._flush()
        finally:
            self._file.close()
            self._file = None
