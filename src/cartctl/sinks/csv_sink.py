"""The CSV trace sink (:func:`csv.writer`, ``str`` of each value): ``write`` keeps the row (another
length than the header's is a ValueError, never a short row); ``idle`` formats the rows kept and
writes and flushes every ``flush_every`` rows, in the loop's thread. A failed write cuts the file
back to its last whole row and raises :class:`~cartctl.errors.OutputError` once (``.error``).
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
from collections.abc import Callable, Sequence
from pathlib import Path

from cartctl.errors import OutputError


class CsvSink:
    """Writes the loop's rows to a CSV file (``str`` of each value: shortest exact floats), in
    blocks of ``flush_every`` rows; ``rows_written`` counts the rows the file holds complete."""

    def __init__(
        self,
        path: str | Path,
        *,
        flush_every: int = 50,
        on_open: Callable[[Sequence[str]], object] | None = None,
    ) -> None:
        self.path = Path(path)
        self._on_open = on_open
        self.flush_every = max(1, int(flush_every))
        self._file: io.FileIO | None = None
        self._rows: list[Sequence[float]] = []
        self._text = io.StringIO()  # the rows formatted and not yet written
        self._writer = csv.writer(self._text, lineterminator="\n")
        self._formatted = 0  # rows in self._text
        self._width = 0  # fields of a row: the header's
        self._size = 0  # bytes of the header and the whole rows in the file
        self.rows_written = 0
        self.error: OutputError | None = None

    def open(self, columns: Sequence[str]) -> None:
        """Create the file (parent folders too) and write the header; then ``on_open(columns)``."""
        self._width = len(columns)  # (rows are taken, and dropped, when the file cannot be made)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = io.FileIO(self.path, "w")  # unbuffered: each block is one write we count
        except OSError as exc:  # its folder gone or made a file since the output check
            self.error = OutputError(self.path, exc.strerror or str(exc), rows=0)
            raise self.error from exc
        self._writer.writerow(columns)
        self._flush()  # the header alone
        if self._on_open is not None:  # (a meta file: with the trace, not before it)
            self._on_open(columns)

    def write(self, row: Sequence[float]) -> None:
        """Keep one row, a value per column (ValueError otherwise, and nothing kept)."""
        if len(row) != self._width:
            raise ValueError(f"{self.path}: a row of {len(row)} fields under {self._width} columns")
        self._rows.append(row)
        if len(self._rows) >= self.flush_every:  # nobody calls idle(): write from here
            self._flush()

    def idle(self) -> None:
        self._format()
        if self._formatted >= self.flush_every:
            self._flush()

    def _format(self) -> None:
        if self._rows:  # str of each value: exact floats (numpy's too), whole ticks
            rows, self._rows = self._rows, []  # taken first: an interrupt never formats one twice
            self._writer.writerows(rows)
            self._formatted += len(rows)

    def _take_text(self) -> bytes:
        data = self._text.getvalue().encode()
        self._text.seek(0)
        self._text.truncate()
        self._formatted = 0
        return data

    def _flush(self) -> None:
        """Write the rows formatted (or the header) in full, or cut the file back to its last
        whole row and raise :class:`OutputError`."""
        self._format()
        file, rows = self._file, self._formatted
        data = self._take_text()
        if file is None:
            return
        done = 0
        try:
            while done < len(data):
                n = file.write(memoryview(data)[done:])
                if not n:  # the system took nothing and said nothing: treat as full
                    raise OSError(28, os.strerror(28))
                done += n
        except OSError as exc:
            whole = data.rfind(b"\n", 0, done) + 1  # bytes of the whole lines that went in
            self.rows_written += max(0, data.count(b"\n", 0, whole) - (rows == 0))
            self._size += whole
            if done > whole:  # no half row left behind (where the device can be cut: not /dev/full)
                with contextlib.suppress(OSError):
                    os.ftruncate(file.fileno(), self._size)
            self._rows, self._file = [], None
            with contextlib.suppress(OSError):
                file.close()
            self.error = OutputError(self.path, exc.strerror or str(exc), rows=self.rows_written)
            raise self.error from exc
        self._size += len(data)
        self.rows_written += rows

    def close(self) -> None:
        if self._file is None:
            return
        self._flush()
        file, self._file = self._file, None
        file.close()
