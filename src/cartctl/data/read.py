"""Reading experiment traces (trace CSV, QRoboticsCenter logs) into a :class:`Trace`, with the
checks of what the numbers mean: finite, increasing time, voltages within the supply, 10 ms ticks.
"""

from __future__ import annotations

import csv
import re
import warnings
from collections.abc import Mapping, Sized
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cartctl.cart import PERIOD_S, SUPPLY_V
from cartctl.data.columns import check_mapping, plan_columns, read_qrc5, read_qrc6
from cartctl.data.tomlfile import FORMATS
from cartctl.data.trace import REQUIRED_COLUMNS, Trace
from cartctl.errors import DataFileError, DataWarning, MissingFileError

SPACING_TOLERANCE_S: float = 0.0015
"""How far a time step may stray from the 10 ms tick (s) before :func:`read_trace` warns (QRC 5
stamps rows with the cart's millis(): 9, 10 and 11 ms are normal, a lost frame gives 20 ms)."""


def read_trace(path: str | Path, mapping: Mapping[str, str] | None = None) -> Trace:
    """Read a trace CSV, a QRC 5 XML log or a QRC 6 CSV log (told by content) as a Trace.

    ``mapping`` is trace column → QRC label or CSV header (:func:`parse_mapping`; the rules
    without one, and the counterparts of a motor left unmapped: docs/file-formats.md). QRC times
    (ms) become seconds from the first row; steps off the 10 ms tick by more than
    :data:`SPACING_TOLERANCE_S` give one :class:`~cartctl.errors.DataWarning`.
    """
    path = Path(path)
    checked = None if mapping is None else check_mapping(mapping)
    kind = _sniff(path)
    values, text = None, None
    if kind == "csv":
        plain = _read_plain_csv(path)
        if plain is None:
            names, header_line, rows, csv_lines, bad = _read_csv(path)
            if len(rows) > 1 and len(rows[-1]) < len(names) and not _ends_with_newline(path):
                rows.pop()  # a write cut short (a kill, a power loss): whole rows were written
                _cut_short(
                    path, "the last row is cut short (the recording stopped mid-write)", rows
                )
        else:
            (names, values, text), header_line, rows, bad = plain, 1, [], None
            csv_lines = list(range(2, len(values) + 2))
        lines: list[int] | None = csv_lines
        time_j, plan = plan_columns(path, "CSV", names, checked, header_line)
        if bad is not None:  # bytes that are not UTF-8 after the header: once it is checked
            raise bad
        expected = f"the header has {len(names)}"
    else:
        log = read_qrc5(path) if kind == "qrc5" else read_qrc6(path)
        if log.truncated:
            why = "the QRC log ends without its closing tags (QRC did not close the recording)"
            _cut_short(path, why, log.rows)
        names, rows = ["time", *log.labels], log.rows
        time_j, plan = plan_columns(path, log.kind, names, checked, None)
        lines = log.row_lines
        expected = f"the log has {len(names)} columns (time and {len(log.labels)} channels)"
    table = Table(path, names, np.empty((0, len(names))), lines)
    table.values = to_floats(table, rows, expected) if values is None else values
    _check_finite(table)
    _check_voltages(table, plan)
    time = table.values[:, time_j]
    _check_increasing(table, time, table.names[time_j], "s" if kind == "csv" else "ms")
    columns = {
        name: np.zeros(len(time)) if j is None else table.values[:, j] for name, j in plan.items()
    }
    if kind != "csv":
        columns["time_s"] = (time - time[0]) / 1000.0
    _warn_spacing(table, columns["time_s"])
    if kind == "qrc5":  # 8 float then 4 int channels after the time
        integers = {name for name, j in plan.items() if j is not None and j > 8}
    else:  # the extras whose every field is written as an integer
        extras = {n: j for n, j in plan.items() if j is not None and n not in REQUIRED_COLUMNS
                  and np.all(table.values[:, j] == np.round(table.values[:, j]))}  # fmt: skip
        if text is not None and extras:  # the fast path's rows, split when they are needed
            rows = [line.split(",") for line in text.split("\n")[1 : len(table.values) + 1]]
        integers = {n for n, j in extras.items() if all(_INTEGER.match(row[j]) for row in rows)}
    integers -= set(REQUIRED_COLUMNS)
    return Trace.from_columns(columns, source=str(path), integer_columns=integers)


_INTEGER = re.compile(r"\s*[+-]?\d+\s*\Z")


def _sniff(path: Path) -> str:
    """Return "csv", "qrc5" or "qrc6" for an existing, non-empty text file."""
    if not path.exists():
        raise MissingFileError(path, "trace file")
    if path.is_dir():
        raise DataFileError(path, "is a directory; expected a trace file (.csv or a QRC log)")
    with path.open("rb") as file:
        head = file.read(4096)
    if b"\0" in head:
        raise DataFileError(path, "binary content; expected a text trace (.csv) or a QRC log")
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff \t\r\n")
    if not text:
        raise DataFileError(
            path,
            f"the file is empty; expected a header row ({','.join(REQUIRED_COLUMNS)}) and one "
            "row per 10 ms tick",
        )
    if text.startswith("<"):
        return "qrc5"
    if _QRC_RECORD.fullmatch(text.split("\n", 1)[0].split(",", 1)[0].strip()):
        return "qrc6"  # a CSV whose first field names a QRC record type
    toml = _CARTCTL_TOML.search(text)
    if toml is not None:
        what = FORMATS.get(toml.group(1), "a cartctl TOML file")
        raise DataFileError(path, f"is {what}, not a trace (.csv or a QRC log)")
    return "csv"


_QRC_RECORD = re.compile(r"Q\w*Record")
_CARTCTL_TOML = re.compile(r'^format = "(cartctl-[a-z-]+/\d+)"', re.MULTILINE)


VOLTAGE_READ_LIMIT_V = SUPPLY_V + 0.5


def _check_voltages(table: Table, plan: Mapping[str, int | None]) -> None:
    """Refuse voltages beyond the supply: another unit (mV) or another channel, not a voltage."""
    for name in ("voltage_a", "voltage_b"):
        j = plan.get(name)
        if j is None:
            continue
        volts = np.abs(table.values[:, j])
        if volts.max(initial=0.0) > VOLTAGE_READ_LIMIT_V:
            i = int(np.argmax(volts > VOLTAGE_READ_LIMIT_V))
            raise table.error(
                i,
                f"{name} is {table.values[i, j]:g} V, beyond the cart's ±{SUPPLY_V:g} V supply: is "
                "the column in mV, or another channel (see --map)?",
                column=table.names[j],
            )


def _check_finite(table: Table) -> None:
    bad = ~np.isfinite(table.values)
    if bad.any():
        i, j = np.unravel_index(np.argmax(bad), bad.shape)
        raise table.error(
            int(i),
            f"{table.values[i, j]} is not a finite number; traces hold finite numbers only",
            column=table.names[j],
        )


def _check_increasing(table: Table, time: np.ndarray, label: str, unit: str) -> None:
    """Refuse time that stands still or goes back, naming the first row where it does."""
    back = np.flatnonzero(np.diff(time) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise table.error(
            i,
            f"time goes from {time[i - 1]:.10g} {unit} to {time[i]:.10g} {unit}; it must "
            "increase from row to row (one row per tick)",
            column=label,
        )


def _warn_spacing(table: Table, time_s: np.ndarray) -> None:
    """Warn once if time steps stray from the 10 ms tick by more than the tolerance."""
    steps = np.diff(time_s)
    off = np.abs(steps - PERIOD_S)
    stray = np.flatnonzero(off > SPACING_TOLERANCE_S)
    if not stray.size:
        return
    worst = int(stray[np.argmax(off[stray])])
    _, worst_at = table.where(worst + 1)
    _, first_at = table.where(int(stray[0]) + 1)
    gaps = steps[steps > 1.5 * PERIOD_S]
    if gaps.size:  # a missing row leaves a step of about two ticks
        missing = int(np.sum(np.round(gaps / PERIOD_S) - 1))
        what = (
            f"about {missing} row(s) are missing (a lost frame leaves a step of about "
            f"{2 * PERIOD_S * 1000:g} ms); identification assumes one row per tick"
        )
    else:
        what = (
            "no row is missing, but the sample clock jitters; identification assumes one row "
            f"per {PERIOD_S * 1000:g} ms tick"
        )
    warnings.warn(
        f"{table.path}: {stray.size} of {steps.size} time steps stray from the "
        f"{PERIOD_S * 1000:g} ms tick by more than {SPACING_TOLERANCE_S * 1000:g} ms; the farthest "
        f"is {steps[worst] * 1000:.4g} ms (at {worst_at}), the first at {first_at}: {what}",
        DataWarning,
        stacklevel=3,
    )


@dataclass
class Table:
    """Numbers read from a file (for QRC, the columns "time" then the channel labels), shape
    (n, len(names)), and the line of each row (None: rows are counted)."""

    path: Path
    names: list[str]
    values: np.ndarray
    row_lines: list[int] | None

    def where(self, i: int) -> tuple[int | None, str]:
        if self.row_lines is None:
            return None, f"row {i + 1}"
        return self.row_lines[i], f"line {self.row_lines[i]}"

    def error(self, i: int, problem: str, column: str | None = None) -> DataFileError:
        line, label = self.where(i)
        if line is None:
            problem = f"{label}: {problem}"
        return DataFileError(self.path, problem, line=line, column=column)


def _read_plain_csv(path: Path) -> tuple[list[str], np.ndarray, str] | None:
    """The fast path: a CSV with its header on line 1, no quote or blank line, and data that
    np.loadtxt reads at once: the names, the numbers and the file's text (row k on line k + 2);
    else None (:func:`_read_csv` reads it row by row: the same numbers, and names any problem)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
        head, n = text[: text.find("\n")], text.count("\n") - text.endswith("\n")
        names = [name.strip() for name in head.split(",")]
        if n < 1 or "\n\n" in text or '"' in head or not all(names) or len(set(names)) < len(names):
            return None
        with path.open(encoding="utf-8-sig") as file:
            values = np.loadtxt(file, delimiter=",", comments=None, ndmin=2, skiprows=1)
    except ValueError:  # a field loadtxt does not read, bytes that are not UTF-8
        return None
    if values.shape != (n, len(names)) or all(map(_is_number, names)):
        return None
    return names, values, text


def _read_csv(
    path: Path,
) -> tuple[list[str], int, list[list[str]], list[int], DataFileError | None]:
    """The header's names and line, and the non-blank rows after it with their lines; bytes
    that are not UTF-8 after the header give the error to raise once the header is checked."""
    rows: list[list[str]] = []
    lines: list[int] = []
    bad, first = None, None
    try:
        with path.open(encoding="utf-8-sig") as file:
            reader = csv.reader(file)
            for row in reader:
                first = first or (reader.line_num if row else None)
                if any(cell.strip() for cell in row) or (not rows and len(row) > 1):
                    rows.append(row)
                    lines.append(reader.line_num)
    except UnicodeDecodeError as err:
        bad = DataFileError(path, f"not UTF-8 text (byte {err.start}); expected CSV")
        bad.__cause__ = err
        if not rows:
            raise bad from err
    if not rows:  # blank quoted fields only, such as '""': the first is a header without names
        raise DataFileError(path, "column 1 of the header has no name", line=first)
    names, number = [name.strip() for name in rows.pop(0)], lines.pop(0)
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
    if not rows:
        raise bad or DataFileError(
            path, "no data rows after the header; expected one per 10 ms tick"
        )
    return names, number, rows, lines, bad


def _ends_with_newline(path: Path) -> bool:
    with path.open("rb") as file:
        file.seek(-1, 2)
        return file.read(1) in (b"\n", b"\r")


def _cut_short(path: Path, why: str, rows: Sized) -> None:
    """Warn that ``path`` ends in a write cut short, of which its whole ``rows`` are read."""
    warnings.warn(f"{path}: {why}; read its {len(rows)} complete rows", DataWarning, stacklevel=3)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def to_floats(table: Table, rows: list[list[str]], expected: str) -> np.ndarray:
    """Rows of text fields as an (n, len(names)) array; an error names the first bad field."""
    names = table.names
    try:
        values = np.array(rows, dtype=np.float64)
    except ValueError:
        values = None
    if values is not None and values.ndim == 2 and values.shape[1] == len(names):
        return values
    for i, fields in enumerate(rows):
        if len(fields) != len(names):
            raise table.error(i, f"{len(fields)} fields, {expected}")
        for name, text in zip(names, fields, strict=True):
            if not _is_number(text):
                value = repr(text.strip()) if text.strip() else "an empty field"
                raise table.error(i, f"{value} is not a number", column=name)
    return np.array(rows, dtype=np.float64)
