"""The experiment trace: the :class:`Trace` type, the ``--map`` form and the CSV writer.

A trace holds, per 10 ms tick k, the voltage *commanded* at tick k (V) and the speed *measured*
at tick k (rad/s) of both motors, and any further columns (the trace columns of
docs/architecture.md). :mod:`cartctl.data` reads traces (CSV and QRoboticsCenter logs);
:func:`write_trace` writes a CSV that reads back bit for bit.
"""

from __future__ import annotations

import csv
import difflib
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np
from numpy.typing import ArrayLike

from cartctl.errors import InputError

__all__ = ["MOTORS", "REQUIRED_COLUMNS", "Trace", "parse_mapping", "write_trace"]

REQUIRED_COLUMNS: tuple[str, ...] = ("time_s", "voltage_a", "voltage_b", "speed_a", "speed_b")
"""The columns every trace has, in the order docs/architecture.md gives them."""

MOTORS: tuple[str, ...] = ("a", "b")
"""The motor names, as in ``voltage_a`` and ``speed_b``."""

_MAP_FORM = "NAME=LABEL[,NAME=LABEL...], e.g. voltage_a=FloatIn2,speed_a=FloatIn0"
_WRITE_CHUNK_ROWS = 65536


@dataclass(frozen=True, eq=False)
class Trace:
    """One experiment: per tick, the time, the commanded voltages and the measured speeds.

    Row k holds the voltage commanded at tick k and the speed measured at tick k (the trace
    columns, docs/architecture.md).
    All arrays are 1-D float64 copies of equal length, made read-only.

    Attributes
    ----------
    time_s : ndarray, shape (n,)
        Time of each tick (s).
    voltage_a, voltage_b : ndarray, shape (n,)
        Voltage commanded at tick k (V); zeros for a motor the experiment did not drive.
    speed_a, speed_b : ndarray, shape (n,)
        Wheel speed measured at tick k (rad/s).
    extra : dict of str to ndarray, shape (n,)
        Further columns in file order (``true_speed_a``, ``tick``, ``reference_a``, ...).
    source : str or None
        The file the trace came from, for messages and provenance.
    integer_columns : frozenset of str
        Extra columns the file held as integers (a log's int channels, a tick counter), which
        :func:`write_trace` writes as such (``100``, not ``100.0``); names not among the extras
        are dropped.

    Raises
    ------
    InputError
        A column that is not 1-D numbers, columns of unequal length, or an extra column with
        no name or with a required column's name.
    """

    time_s: np.ndarray
    voltage_a: np.ndarray
    voltage_b: np.ndarray
    speed_a: np.ndarray
    speed_b: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    source: str | None = None
    integer_columns: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        for name in REQUIRED_COLUMNS:
            object.__setattr__(self, name, _as_column(name, getattr(self, name)))
        extra: dict[str, np.ndarray] = {}
        for name, values in self.extra.items():
            if not isinstance(name, str) or not name.strip():
                raise InputError(f"extra column name {name!r} is not a usable column name")
            if name in REQUIRED_COLUMNS:
                raise InputError(f"extra column {name!r} repeats a required column; drop it")
            extra[name] = _as_column(name, values)
        object.__setattr__(self, "extra", extra)
        object.__setattr__(self, "integer_columns", frozenset(self.integer_columns) & set(extra))
        if self.source is not None:
            object.__setattr__(self, "source", str(self.source))
        n = len(self.time_s)
        for name, values in self.columns().items():
            if len(values) != n:
                raise InputError(
                    f"column {name!r} has {len(values)} values but time_s has {n}; "
                    "every column needs one value per tick"
                )

    def __len__(self) -> int:
        return len(self.time_s)

    def __repr__(self) -> str:
        names = ", ".join(self.columns())
        return f"Trace({len(self)} ticks, columns [{names}], source={self.source!r})"

    def voltage(self, motor: str) -> np.ndarray:
        """The voltage commanded to motor ``'a'`` or ``'b'`` at each tick (V), shape (n,)."""
        return getattr(self, f"voltage_{_motor(motor)}")

    def speed(self, motor: str) -> np.ndarray:
        """The speed of motor ``'a'`` or ``'b'`` measured at each tick (rad/s), shape (n,)."""
        return getattr(self, f"speed_{_motor(motor)}")

    def column(self, name: str) -> np.ndarray:
        """A required or extra column by name, shape (n,).

        Raises
        ------
        InputError
            No such column; the message lists the trace's columns.
        """
        columns = self.columns()
        if name not in columns:
            where = f" from {self.source}" if self.source else ""
            raise InputError(f"no column {name!r} in the trace{where}; it has {', '.join(columns)}")
        return columns[name]

    def columns(self) -> dict[str, np.ndarray]:
        """All columns by name: the required ones (:data:`REQUIRED_COLUMNS` order), the extras."""
        return {name: getattr(self, name) for name in REQUIRED_COLUMNS} | self.extra

    @property
    def period_s(self) -> float:
        """The median time step (s).

        Raises
        ------
        InputError
            Fewer than two ticks.
        """
        if len(self) < 2:
            raise InputError(f"a trace needs two ticks or more to have a period; has {len(self)}")
        return float(np.median(np.diff(self.time_s)))

    @classmethod
    def from_columns(
        cls,
        columns: Mapping[str, ArrayLike],
        source: str | None = None,
        integer_columns: Collection[str] = (),
    ) -> Trace:
        """Build a trace from named columns.

        Parameters
        ----------
        columns : mapping of str to array_like, each shape (n,)
            All of :data:`REQUIRED_COLUMNS`, plus any extras (kept in the mapping's order).
        source : str, optional
            Where the columns came from.
        integer_columns : collection of str
            Extra columns held as integers (see :class:`Trace`).

        Raises
        ------
        InputError
            A required column is missing, or as for :class:`Trace`.
        """
        missing = [name for name in REQUIRED_COLUMNS if name not in columns]
        if missing:
            raise InputError(
                f"missing required column(s) {', '.join(missing)}; a trace needs "
                f"{', '.join(REQUIRED_COLUMNS)} (got {', '.join(columns) or 'none'})"
            )
        # array_like as the fields take it: __post_init__ makes each a float64 array
        given = cast("Mapping[str, np.ndarray]", columns)
        extra = {name: values for name, values in given.items() if name not in REQUIRED_COLUMNS}
        required = {name: given[name] for name in REQUIRED_COLUMNS}
        return cls(**required, extra=extra, source=source,
                   integer_columns=frozenset(integer_columns))  # fmt: skip


def _as_column(name: str, values: ArrayLike) -> np.ndarray:
    """Copy one column into a read-only 1-D float64 array."""
    try:
        array = np.array(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputError(f"column {name!r} must hold numbers ({err})") from err
    if array.ndim != 1:
        raise InputError(
            f"column {name!r} must be 1-D (one value per tick), got shape {array.shape}"
        )
    array.flags.writeable = False
    return array


def _motor(motor: str) -> str:
    if motor not in MOTORS:
        raise InputError(f"motor must be 'a' or 'b', got {motor!r}")
    return motor


def parse_mapping(text: str) -> dict[str, str]:
    """Parse a column mapping as given on the command line (``--map``).

    Parameters
    ----------
    text : str
        ``NAME=LABEL`` items separated by commas, e.g. ``"voltage_a=FloatIn2,speed_a=FloatIn0"``.
        NAME is a trace column: a required one, or any identifier for an extra column.
        LABEL is a QRC channel label or a CSV header name; spaces around items are ignored.

    Returns
    -------
    dict of str to str
        Trace column name → label, in the order given.

    Raises
    ------
    InputError
        An item without ``=``, an empty name or label, a name that is not an identifier or is
        a near miss of a required column (``speed_A``), or a name given twice.
    """
    mapping: dict[str, str] = {}
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        name, equals, label = (part.strip() for part in item.partition("="))
        if not equals or not name or not label:
            raise InputError(f"bad column mapping item {item!r}; expected {_MAP_FORM}")
        _check_name(name)
        if name in mapping:
            raise InputError(
                f"column {name!r} is mapped twice ({mapping[name]!r} and {label!r}); map it once"
            )
        mapping[name] = label
    if not mapping:
        raise InputError(f"empty column mapping {text!r}; expected {_MAP_FORM}")
    return mapping


def _check_name(name: object) -> None:
    """Refuse a mapping key that is not a column name, or that looks like a mistyped one."""
    if not isinstance(name, str) or not name.isidentifier():
        raise InputError(
            f"{name!r} is not a column name; expected a name such as voltage_a, speed_b or "
            f"reference_a, in {_MAP_FORM}"
        )
    near = difflib.get_close_matches(name.lower(), REQUIRED_COLUMNS, n=1, cutoff=0.8)
    if name not in REQUIRED_COLUMNS and near:
        raise InputError(
            f"unknown column {name!r} in the mapping; did you mean {near[0]!r}? "
            f"The required columns are {', '.join(REQUIRED_COLUMNS)}"
        )


def write_trace(
    trace: Trace, path: str | Path, *, integer_columns: Collection[str] | None = None
) -> None:
    """Write a trace as CSV (the trace columns), creating parent directories.

    The header row names the required columns then the extras; each value is written as the
    shortest text that reads back to the same float64, so a round trip is bit-exact. Integer
    columns (``trace.integer_columns`` unless given: a log's int channels, a tick counter) are
    written without a fraction: ``100``, not ``100.0``.

    Parameters
    ----------
    trace : Trace
        At least one tick, finite values, strictly increasing time: what :func:`read_trace`
        accepts.
    path : str or Path
        The ``.csv`` file to write (overwritten if it exists).
    integer_columns : collection of str, optional
        Columns to write as integers, each of whole numbers only; default
        ``trace.integer_columns``.

    Raises
    ------
    InputError
        An empty trace, a column name that CSV cannot carry, a value that is not finite, time
        that does not increase, or a fraction in an integer column.
    """
    path = Path(path)
    columns = trace.columns()
    for name in columns:
        if name != name.strip() or any(c in name for c in ',"\r\n'):
            raise InputError(
                f"cannot write column name {name!r} to {path}: no commas, quotes, line breaks "
                "or surrounding spaces"
            )
    if not len(trace):
        raise InputError(f"cannot write {path}: the trace has no ticks")
    data = np.column_stack(list(columns.values()))
    bad = ~np.isfinite(data)
    if bad.any():
        i, j = (int(k) for k in np.unravel_index(np.argmax(bad), bad.shape))
        raise InputError(
            f"cannot write {path}: column {list(columns)[j]!r} holds {data[i, j]} at tick {i}; "
            "trace files hold finite numbers only"
        )
    back = np.flatnonzero(np.diff(trace.time_s) <= 0)
    if back.size:
        raise InputError(
            f"cannot write {path}: time_s does not increase at tick {back[0] + 1} "
            f"({float(trace.time_s[back[0]])!r} s, then {float(trace.time_s[back[0] + 1])!r} s)"
        )
    integers = trace.integer_columns if integer_columns is None else integer_columns
    whole = [j for j, name in enumerate(columns) if name in integers]
    for j in whole:
        if np.any(data[:, j] != np.round(data[:, j])) or np.any(np.abs(data[:, j]) > 2.0**53):
            raise InputError(
                f"cannot write column {list(columns)[j]!r} as integers: it has fractions"
            )
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", encoding="utf-8", newline="") as file:
        writer = csv.writer(file, lineterminator="\n")  # str of a Python float: shortest exact
        writer.writerow(columns)
        for start in range(0, len(data), _WRITE_CHUNK_ROWS):
            block = data[start : start + _WRITE_CHUNK_ROWS].tolist()
            if whole:
                for row in block:
                    for j in whole:
                        row[j] = int(row[j])
            writer.writerows(block)
