"""The CSV trace sink: contract 1 plus the closed-loop columns, flushed at least once a second.

``write`` keeps the tick's row (a tuple of floats, nothing formatted); ``idle``, which the loop
calls after the tick's compute time is taken, formats the rows kept so far and, every
``flush_every`` rows (default 50: twice a second at 10 ms), writes them and flushes the file, so a
crash loses at most the last block. Everything happens in the loop's thread (a writer thread would
compete for the GIL and add wake-up jitter); formatting a row costs some 5–30 µs, which the
command no longer waits for, and a 50-row block formatted at once would have put some 300 µs into
every 50th tick, the loop's 99th percentile. ``close`` writes whatever is left.
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
        self._rows: list[Sequence[float]] = []
        self._lines: list[str] = []
        self._template = ""
        self.rows_written = 0

    def open(self, columns: Sequence[str]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("w", encoding="utf-8", newline="")
        self._file.write(",".join(columns) + "\n")
        self._template = ",".join(["%s"] * len(columns))  # %s is str(): 10 % under a join
        self._file.flush()

    def write(self, row: Sequence[float]) -> None:
        rows = self._rows
        rows.append(row)
        if len(rows) >= self.flush_every:  # nobody calls idle(): write from here, as before
            self._flush()

    def idle(self) -> None:
        """Format the rows kept so far; write and flush once a block is complete."""
        self._format()
        if len(self._lines) >= self.flush_every:
            self._flush()

    def _format(self) -> None:
        lines, template = self._lines, self._template
        for row in self._rows:  # str: exact floats (numpy's too), whole ticks
            try:
                lines.append(template % tuple(row))
            except TypeError:  # a row of another length than the header's
                lines.append(",".join(map(str, row)))
        self._rows = []

    def _flush(self) -> None:
        self._format()
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
