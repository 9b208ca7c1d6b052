"""A table of numbers from a text file, with errors that name the line, row and column.

:func:`cartctl.data.read.read_trace` turns a trace CSV file's rows, or a QRC log's samples,
into a :class:`Table` here before it decides which columns become which trace column
(:mod:`cartctl.data.columns`). Parsing goes through :mod:`csv` and :func:`numpy.loadtxt`; the slow
field-by-field scan runs only to name the first field that is not a number.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from cartctl.data.trace import REQUIRED_COLUMNS
from cartctl.errors import DataFileError

__all__ = ["Table", "Where", "read_csv_header", "read_csv_rows", "to_floats"]


class Where:
    """Where row i of a file's data is: its line, or its row number when lines are unknown."""

    def __init__(
        self,
        path: Path,
        *,
        row_lines: list[int] | None = None,
        header_line: int | None = None,
    ) -> None:
        self.path = path
        self.row_lines = row_lines
        self.header_line = header_line

    def __call__(self, i: int) -> tuple[int | None, str]:
        if self.row_lines is None and self.header_line is not None:
            self.row_lines = _data_lines(self.path, self.header_line)[1]
        if self.row_lines is None:
            return None, f"row {i + 1}"
        return self.row_lines[i], f"line {self.row_lines[i]}"

    def error(self, i: int, problem: str, column: str | None = None) -> DataFileError:
        line, label = self(i)
        if line is None:
            problem = f"{label}: {problem}"
        return DataFileError(self.path, problem, line=line, column=column)


@dataclass
class Table:
    """Numbers read from a file, before they become trace columns."""

    path: Path
    names: list[str]  # the file's column names; for QRC, "time" then the channel labels
    values: np.ndarray  # shape (n, len(names))
    where: Where


def read_csv_header(path: Path) -> tuple[list[str], int]:
    """The CSV header's names and line; also make sure that data rows follow."""
    with _open_text(path) as file:
        number, line = 1, file.readline()
        while line and not line.strip():
            number, line = number + 1, file.readline()
        names = [name.strip() for name in next(csv.reader([line]))]
        if all(_is_number(name) for name in names):
            raise DataFileError(
                path,
                "no header row: the first row holds numbers; expected column names first, "
                f"e.g. {','.join(REQUIRED_COLUMNS)}",
                line=number,
            )
        for k, name in enumerate(names):
            if not name:
                raise DataFileError(path, f"column {k + 1} of the header has no name", line=number)
            if names.index(name) != k:
                raise DataFileError(
                    path, f"column name {name!r} appears twice; names must be unique", line=number
                )
        if not any(line.strip() for line in file):
            raise DataFileError(path, "no data rows after the header; expected one per 10 ms tick")
    return names, number


def read_csv_rows(path: Path, names: list[str], header_line: int) -> Table:
    """The numbers after the header: np.loadtxt first, and on failure a scan for the culprit."""
    with _open_text(path) as file:
        for _ in range(header_line):
            file.readline()
        try:
            values = np.loadtxt(file, delimiter=",", comments=None, ndmin=2, dtype=np.float64)
        except ValueError:
            values = None
    if values is not None and values.shape[1] == len(names):
        return Table(path, names, values, Where(path, header_line=header_line))
    rows, lines = _data_lines(path, header_line)
    where = Where(path, row_lines=lines)
    return Table(path, names, to_floats(where, rows, names, f"the header has {len(names)}"), where)


def _data_lines(path: Path, header_line: int) -> tuple[list[list[str]], list[int]]:
    """The non-blank rows after the header (read with :mod:`csv`) and their line numbers."""
    rows: list[list[str]] = []
    lines: list[int] = []
    with _open_text(path) as file:
        reader = csv.reader(file)
        for row in reader:
            if reader.line_num > header_line and any(cell.strip() for cell in row):
                rows.append(row)
                lines.append(reader.line_num)
    return rows, lines


@contextmanager
def _open_text(path: Path) -> Iterator[TextIO]:
    """Open a text file, turning a decoding failure into a DataFileError."""
    try:
        with path.open(encoding="utf-8-sig") as file:
            yield file
    except UnicodeDecodeError as err:
        raise DataFileError(path, f"not UTF-8 text (byte {err.start}); expected CSV") from err


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def to_floats(where: Where, rows: list[list[str]], names: list[str], expected: str) -> np.ndarray:
    """Convert rows of text fields to an (n, len(names)) array, naming the first bad field."""
    try:
        values = np.array(rows, dtype=np.float64)
    except ValueError:
        values = None
    if values is not None and values.ndim == 2 and values.shape[1] == len(names):
        return values
    for i, fields in enumerate(rows):
        if len(fields) != len(names):
            raise where.error(i, f"{len(fields)} fields, {expected}")
        for name, text in zip(names, fields, strict=True):
            if not _is_number(text):
                value = repr(text.strip()) if text.strip() else "an empty field"
                raise where.error(i, f"{value} is not a number", column=name)
    return np.array(rows, dtype=np.float64)
