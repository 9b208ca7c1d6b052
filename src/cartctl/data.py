"""Reading experiment traces: contract-1 CSV and QRoboticsCenter logs into a :class:`Trace`.

The first stage of the pipeline (data → identify → models/ → design → controllers/ → runtime →
logs/). A trace holds, per 10 ms tick k, the voltage *commanded* at tick k (V) and the speed
*measured* at tick k (rad/s) of both motors (the CSV columns are in the README, "Traces").
:func:`read_trace` reads contract-1 CSV files and QRoboticsCenter logs (whose layout
:mod:`cartctl.qrc` parses), optionally mapping QRC labels or foreign CSV headers onto trace
columns. The type and its writer are in :mod:`cartctl.trace` (and importable from here).
"""

from __future__ import annotations

import csv
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from cartctl import qrc
from cartctl.cart import PERIOD_S as TS_S
from cartctl.cart import SUPPLY_V
from cartctl.errors import DataFileError, DataWarning, InputError, MissingFileError
from cartctl.trace import (
    _MAP_FORM,
    MOTORS,
    REQUIRED_COLUMNS,
    Trace,
    _check_name,
    parse_mapping,
    write_trace,
)

__all__ = [
    "MOTORS",
    "REQUIRED_COLUMNS",
    "SPACING_TOLERANCE_S",
    "Trace",
    "parse_mapping",
    "read_trace",
    "write_trace",
]

SPACING_TOLERANCE_S: float = 0.0015
"""How far a time step may stray from the 10 ms tick (s) before :func:`read_trace` warns.

QRC 5 stamps rows with the cart's millis(), so steps of 9, 10 and 11 ms are normal; a lost frame
gives about 20 ms."""


class _Where:
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
class _Table:
    """Numbers read from a file, before they become trace columns."""

    path: Path
    names: list[str]  # the file's column names; for QRC, "time" then the channel labels
    values: np.ndarray  # shape (n, len(names))
    where: _Where


def read_trace(path: str | Path, mapping: Mapping[str, str] | None = None) -> Trace:
    """Read an experiment trace: contract-1 CSV, a QRC 5 XML log or a QRC 6 CSV log.

    The format is told from the content: an XML root ``<QGPIORecord>`` is QRC 5, a first line
    starting with ``QGPIORecord`` is QRC 6, anything else is contract-1 CSV. QRC times (ms) become
    seconds from the first row. Time steps that stray from the 10 ms tick by more than
    :data:`SPACING_TOLERANCE_S` give one :class:`~cartctl.errors.DataWarning` per file.

    Parameters
    ----------
    path : str or Path
        The file.
    mapping : mapping of str to str, optional
        Trace column name → QRC label or CSV header name (see :func:`parse_mapping`). Without
        one, a CSV must have the contract's columns, and a QRC log's labels that equal trace
        column names are used (compared in lower case, with other characters read as ``_``). With one, or for any QRC log, a motor whose
        voltage and speed are both unmapped is filled with zeros, but at least one motor must
        have both. Unmapped channels and columns are kept as extras (QRC labels made into names
        such as ``floatin3``) unless their name is taken.

    Returns
    -------
    Trace
        With ``source`` set to ``path``.

    Raises
    ------
    MissingFileError
        No such file.
    DataFileError
        Content that is not a trace, naming the file and the line, row or column.
    InputError
        A malformed mapping.
    """
    path = Path(path)
    checked = None if mapping is None else _check_mapping(mapping)
    kind = _sniff(path)
    if kind == "csv":
        names, header_line = _read_header(path)
        time_j, plan = _plan(path, "CSV", names, checked, header_line)
        table = _read_csv_rows(path, names, header_line)
    else:
        log = qrc.read_qrc5(path) if kind == "qrc5" else qrc.read_qrc6(path)
        if log.truncated:
            warnings.warn(
                f"{path}: the QRC log ends without its closing tags (QRC did not close the "
                f"recording); read its {len(log.rows)} complete rows",
                DataWarning,
                stacklevel=2,
            )
        names = ["time", *log.labels]
        time_j, plan = _plan(path, log.kind, names, checked, None)
        where = _Where(path, row_lines=log.row_lines)
        expected = f"the log has {len(names)} columns (time and {len(log.labels)} channels)"
        table = _Table(path, names, _to_floats(where, log.rows, names, expected), where)
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
    return Trace.from_columns(columns, source=str(path))


def _check_mapping(mapping: Mapping[str, str]) -> dict[str, str]:
    checked: dict[str, str] = {}
    for name, label in mapping.items():
        _check_name(name)
        if not isinstance(label, str) or not label.strip():
            raise InputError(f"the mapping gives {name} no label ({label!r}); expected {_MAP_FORM}")
        checked[name] = label.strip()
    return checked


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
    return qrc.detect(text) or "csv"


def _read_header(path: Path) -> tuple[list[str], int]:
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


def _read_csv_rows(path: Path, names: list[str], header_line: int) -> _Table:
    """The numbers after the header: np.loadtxt first, and on failure a scan for the culprit."""
    with _open_text(path) as file:
        for _ in range(header_line):
            file.readline()
        try:
            values = np.loadtxt(file, delimiter=",", comments=None, ndmin=2, dtype=np.float64)
        except ValueError:
            values = None
    if values is not None and values.shape[1] == len(names):
        return _Table(path, names, values, _Where(path, header_line=header_line))
    rows, lines = _data_lines(path, header_line)
    where = _Where(path, row_lines=lines)
    return _Table(
        path, names, _to_floats(where, rows, names, f"the header has {len(names)}"), where
    )


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


def _to_floats(where: _Where, rows: list[list[str]], names: list[str], expected: str) -> np.ndarray:
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


VOLTAGE_READ_LIMIT_V = SUPPLY_V + 0.5
"""A voltage in data beyond this (V) was never on a motor of the cart (its supply is ±12 V)."""


def _check_voltages(table: _Table, plan: Mapping[str, int | None]) -> None:
    """Refuse voltages beyond the supply: another unit (mV) or another channel, not a voltage."""
    for name in ("voltage_a", "voltage_b"):
        j = plan.get(name)
        if j is None:
            continue
        volts = np.abs(table.values[:, j])
        if volts.max(initial=0.0) > VOLTAGE_READ_LIMIT_V:
            i = int(np.argmax(volts > VOLTAGE_READ_LIMIT_V))
            raise table.where.error(
                i,
                f"{name} is {table.values[i, j]:g} V, beyond the cart's ±{SUPPLY_V:g} V supply: is "
                "the column in mV, or another channel (see --map)?",
                column=table.names[j],
            )


def _check_finite(table: _Table) -> None:
    bad = ~np.isfinite(table.values)
    if bad.any():
        i, j = np.unravel_index(np.argmax(bad), bad.shape)
        raise table.where.error(
            int(i),
            f"{table.values[i, j]} is not a finite number; traces hold finite numbers only",
            column=table.names[j],
        )


def _plan(
    path: Path, kind: str, names: list[str], mapping: dict[str, str] | None, header_line: int | None
) -> tuple[int, dict[str, int | None]]:
    """Decide where each trace column comes from: a file column's index, or None for zeros.

    For QRC logs ``names`` starts with the time column, which always gives time_s. Returns the
    time column's index and the plan, in trace column order.
    """
    if kind == "CSV" and mapping is None:
        missing = [name for name in REQUIRED_COLUMNS if name not in names]
        if missing:
            hint = ""
            if len(names) == 1 and (";" in names[0] or "\t" in names[0]):
                hint = "; the columns seem separated by ';' or tabs, but trace files use ','"
            raise DataFileError(
                path,
                f"missing required column(s) {', '.join(missing)}; the header has "
                f"{', '.join(names)}; a trace needs {', '.join(REQUIRED_COLUMNS)}{hint}",
                line=header_line,
            )
        plan: dict[str, int | None] = {name: names.index(name) for name in REQUIRED_COLUMNS}
        plan |= {n: j for j, n in enumerate(names) if n not in REQUIRED_COLUMNS}
        return names.index("time_s"), plan
    mapping = mapping or {}
    first = 0 if kind == "CSV" else 1  # QRC: names[0] is the time column
    what = "column" if kind == "CSV" else "channel"
    listing = ", ".join(names[first:])
    if first and "time_s" in mapping:
        raise DataFileError(
            path,
            f"a {kind} log carries its own time (ms), which becomes time_s; "
            f"drop time_s={mapping['time_s']} from the mapping",
        )
    auto = [n if not first else qrc.column_name(n, j - 1, kind) for j, n in enumerate(names)]
    source = {"time_s": 0} if first else {}
    for name, label in mapping.items():
        hits = [j for j, n in enumerate(names) if n == label and j >= first]
        if len(hits) != 1:
            problem = "lacks" if not hits else f"has {len(hits)} times"
            raise DataFileError(
                path,
                f"the mapping {name}={label} names {what} {label!r}, which this {kind} file "
                f"{problem}; its {what}s are {listing}",
            )
        source[name] = hits[0]
    # Where the mapping is silent, take a column named like the trace column; but a motor's
    # voltage or speed only if its partner is mapped or named too (else it half-maps a motor).
    explicit = set(source.values())
    partners = {f"voltage_{m}": f"speed_{m}" for m in MOTORS}
    partners |= {speed: voltage for voltage, speed in partners.items()}
    for name in REQUIRED_COLUMNS:
        if name in source or name not in auto[first:] or auto.index(name) in explicit:
            continue
        partner = partners.get(name)
        if partner is None or partner in source or partner in auto[first:]:
            source[name] = auto.index(name)
    if "time_s" not in source:
        raise DataFileError(
            path,
            f"no time column: the header has {listing}; say which column holds the time (s) "
            "with --map time_s=<column>",
            line=header_line,
        )
    for motor in MOTORS:
        pair = [f"voltage_{motor}", f"speed_{motor}"]
        have = [name for name in pair if name in source]
        if len(have) == 1:
            lack = pair[1 - pair.index(have[0])]
            raise DataFileError(
                path,
                f"{have[0]} comes from {what} {names[source[have[0]]]!r} but {lack} from none; "
                f"map both of motor {motor}'s columns, or neither",
            )
    if not any(f"voltage_{motor}" in source for motor in MOTORS):
        example = _guess_mapping(names[first:])
        raise DataFileError(
            path,
            f"no mapping for voltage/speed columns; this {kind} file has {what}s {listing}; "
            f"say which is which with --map {example}",
        )
    plan = {name: source.get(name) for name in REQUIRED_COLUMNS}
    taken = set(REQUIRED_COLUMNS) | set(source)
    used = set(source.values())
    for j in range(first, len(names)):  # extras, in file order
        plan |= {name: k for name, k in source.items() if k == j and name not in plan}
        if j not in used and auto[j] not in taken:
            name, suffix = auto[j], 2
            while name in plan:
                name, suffix = f"{auto[j]}_{suffix}", suffix + 1
            plan[name] = j
    return source["time_s"], plan


def _check_increasing(table: _Table, time: np.ndarray, label: str, unit: str) -> None:
    """Refuse time that stands still or goes back, naming the first row where it does."""
    back = np.flatnonzero(np.diff(time) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise table.where.error(
            i,
            f"time goes from {time[i - 1]:.10g} {unit} to {time[i]:.10g} {unit}; it must "
            "increase from row to row (one row per tick)",
            column=label,
        )


_VOLTAGE_WORDS = ("volt", "voltage", "u_", "pwm")
_SPEED_WORDS = ("speed", "omega", "vel", "rad_s", "rads")


def _guess_mapping(labels: Sequence[str]) -> str:
    """A ``--map`` example from labels that say what they are; placeholders when none do.

    Only a label's own words count (``voltA``, ``speedA``): a guess by position would wire a
    voltage to whatever channel sits there (an error, a reference).
    """

    def first(words: tuple[str, ...]) -> str | None:
        return next((lab for lab in labels if any(w in lab.lower() for w in words)), None)

    volt, speed = first(_VOLTAGE_WORDS), first(_SPEED_WORDS)
    if volt is None or speed is None:
        return "voltage_a=<label>,speed_a=<label> (no label says which channel is which)"
    return f"voltage_a={volt},speed_a={speed}"


def _warn_spacing(table: _Table, time_s: np.ndarray) -> None:
    """Warn once if time steps stray from the 10 ms tick by more than the tolerance."""
    steps = np.diff(time_s)
    off = np.abs(steps - TS_S)
    stray = np.flatnonzero(off > SPACING_TOLERANCE_S)
    if not stray.size:
        return
    worst = int(stray[np.argmax(off[stray])])
    _, worst_at = table.where(worst + 1)
    _, first_at = table.where(int(stray[0]) + 1)
    gaps = steps[steps > 1.5 * TS_S]
    if gaps.size:  # a missing row leaves a step of about two ticks
        missing = int(np.sum(np.round(gaps / TS_S) - 1))
        what = (
            f"about {missing} row(s) are missing (a lost frame leaves a step of about "
            f"{2 * TS_S * 1000:g} ms); identification assumes one row per tick"
        )
    else:
        what = (
            "no row is missing, but the sample clock jitters; identification assumes one row "
            f"per {TS_S * 1000:g} ms tick"
        )
    warnings.warn(
        f"{table.path}: {stray.size} of {steps.size} time steps stray from the "
        f"{TS_S * 1000:g} ms tick by more than {SPACING_TOLERANCE_S * 1000:g} ms; the farthest "
        f"is {steps[worst] * 1000:.4g} ms (at {worst_at}), the first at {first_at}: {what}",
        DataWarning,
        stacklevel=3,
    )
