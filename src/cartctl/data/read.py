"""Reading experiment traces: trace CSV and QRoboticsCenter logs into a :class:`Trace`.

The first stage of the pipeline (data → identify → models/ → design → controllers/ → runtime →
logs/). A trace holds, per 10 ms tick k, the voltage *commanded* at tick k (V) and the speed
*measured* at tick k (rad/s) of both motors (the CSV columns: docs/architecture.md, "Trace columns").
:func:`read_trace` reads trace CSV files and QRoboticsCenter logs (whose layout
:mod:`cartctl.data.qrc` parses), optionally mapping QRC labels or foreign CSV headers onto trace
columns. The file's numbers come from :mod:`cartctl.data.table`, the choice of columns from
:mod:`cartctl.data.columns`; the checks of what the numbers mean (finite, increasing time, voltages
within the supply, 10 ms spacing) are here.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from cartctl.cart import PERIOD_S, SUPPLY_V
from cartctl.data.columns import check_mapping, plan_columns
from cartctl.data.qrc import detect, read_qrc5, read_qrc6
from cartctl.data.table import (
    Table,
    Where,
    _data_lines,
    read_csv_header,
    read_csv_rows,
    to_floats,
)
from cartctl.data.tomlfile import FORMATS
from cartctl.data.trace import REQUIRED_COLUMNS, Trace
from cartctl.errors import DataFileError, DataWarning, MissingFileError

__all__ = ["SPACING_TOLERANCE_S", "VOLTAGE_READ_LIMIT_V", "read_trace"]

SPACING_TOLERANCE_S: float = 0.0015
"""How far a time step may stray from the 10 ms tick (s) before :func:`read_trace` warns.

QRC 5 stamps rows with the cart's millis(), so steps of 9, 10 and 11 ms are normal; a lost frame
gives about 20 ms."""


def read_trace(path: str | Path, mapping: Mapping[str, str] | None = None) -> Trace:
    """Read an experiment trace: a trace CSV, a QRC 5 XML log or a QRC 6 CSV log.

    The format is told from the content: an XML root ``<QGPIORecord>`` is QRC 5, a first line
    starting with ``QGPIORecord`` is QRC 6, anything else is a trace CSV. QRC times (ms) become
    seconds from the first row. Time steps that stray from the 10 ms tick by more than
    :data:`SPACING_TOLERANCE_S` give one :class:`~cartctl.errors.DataWarning` per file.

    Parameters
    ----------
    path : str or Path
        The file.
    mapping : mapping of str to str, optional
        Trace column name → QRC label or CSV header name (see :func:`parse_mapping`). Without
        one, a CSV must have the trace columns, and a QRC log's labels that equal trace
        column names are used (compared in lower case, with other characters read as ``_``).
        A ``cartctl monitor`` trace (``time_s, tick`` and its labels) is read by its labels:
        ``speed_a``, ``speedA`` or ``Speed_A`` is speed_a (see
        :func:`~cartctl.data.columns.monitor_mapping`). With a mapping, or for any QRC log, a
        motor whose voltage and speed are both unmapped takes the channels named like the other
        motor's mapped ones with its own letter (``voltA`` → ``voltB``) when the file has both,
        else it is filled with zeros; at least one motor must have both. Unmapped channels and
        columns are kept as extras under their labels, case kept (QRC labels made into names
        such as ``FloatIn3`` or ``voltage_B_V``), unless their name is taken.

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
    checked = None if mapping is None else check_mapping(mapping)
    kind = _sniff(path)
    if kind == "csv":
        names, header_line = read_csv_header(path)
        time_j, plan = plan_columns(path, "CSV", names, checked, header_line)
        table = read_csv_rows(path, names, header_line)
    else:
        log = read_qrc5(path) if kind == "qrc5" else read_qrc6(path)
        if log.truncated:
            warnings.warn(
                f"{path}: the QRC log ends without its closing tags (QRC did not close the "
                f"recording); read its {len(log.rows)} complete rows",
                DataWarning,
                stacklevel=2,
            )
        names = ["time", *log.labels]
        time_j, plan = plan_columns(path, log.kind, names, checked, None)
        where = Where(path, row_lines=log.row_lines)
        expected = f"the log has {len(names)} columns (time and {len(log.labels)} channels)"
        table = Table(path, names, to_floats(where, log.rows, names, expected), where)
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
        integers = {name for name, j in plan.items() if j is not None and j > QRC5_FLOATS}
    else:  # the columns whose every field is written as an integer
        text = (lambda: _data_lines(path, header_line)[0]) if kind == "csv" else (lambda: log.rows)
        integers = _integer_text(table, plan, text)
    integers -= set(REQUIRED_COLUMNS)
    return Trace.from_columns(columns, source=str(path), integer_columns=integers)


QRC5_FLOATS = 8
"""A QRC 5 log's float channels come first (after the time), its int channels after them."""
_INTEGER = re.compile(r"\s*[+-]?\d+\s*\Z")


def _integer_text(
    table: Table, plan: Mapping[str, int | None], text: Callable[[], list[list[str]]]
) -> set[str]:
    """The extra columns of whole numbers whose every field is written without '.' or exponent.

    ``text`` gives the rows' fields; it is called only when some extra column holds whole
    numbers only.
    """
    values = table.values
    whole = {name: j for name, j in plan.items() if j is not None and name not in REQUIRED_COLUMNS
             and np.all(values[:, j] == np.round(values[:, j]))}  # fmt: skip
    if not whole:
        return set()
    rows = text()
    return {name for name, j in whole.items() if all(_INTEGER.match(row[j]) for row in rows)}


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
    kind = detect(text)
    toml = _CARTCTL_TOML.search(text) if kind is None else None
    if toml is not None:
        what = FORMATS.get(toml.group(1), "a cartctl TOML file")
        raise DataFileError(path, f"is {what}, not a trace (.csv or a QRC log)")
    return kind or "csv"


_CARTCTL_TOML = re.compile(r'^format = "(cartctl-[a-z-]+/\d+)"', re.MULTILINE)
"""The format line of a model, controller or trace meta file."""


VOLTAGE_READ_LIMIT_V = SUPPLY_V + 0.5
"""A voltage in data beyond this (V) was never on a motor of the cart (its supply is ±12 V)."""


def _check_voltages(table: Table, plan: Mapping[str, int | None]) -> None:
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


def _check_finite(table: Table) -> None:
    bad = ~np.isfinite(table.values)
    if bad.any():
        i, j = np.unravel_index(np.argmax(bad), bad.shape)
        raise table.where.error(
            int(i),
            f"{table.values[i, j]} is not a finite number; traces hold finite numbers only",
            column=table.names[j],
        )


def _check_increasing(table: Table, time: np.ndarray, label: str, unit: str) -> None:
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
