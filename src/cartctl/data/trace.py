"""The experiment trace (:class:`Trace`), the ``--map`` form, the CSV writer, and the trace's
*meta* file (``logs/ground.csv`` → ``logs/ground.meta.toml``, keys in docs/file-formats.md): the
loop it was recorded in, whose delay ``identify`` carries into the model file (none: unknown).
"""

from __future__ import annotations

import csv
import difflib
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, cast

import numpy as np
import tomli_w
from numpy.typing import ArrayLike

from cartctl.data.outputs import writing
from cartctl.data.tomlfile import TRACE_META_FORMAT, read_loop_delay, read_toml
from cartctl.errors import DataFileError, InputError

REQUIRED_COLUMNS: tuple[str, ...] = ("time_s", "voltage_a", "voltage_b", "speed_a", "speed_b")
"""The columns every trace has (docs/architecture.md, trace columns)."""

MOTORS: tuple[str, ...] = ("a", "b")

_MAP_FORM = "NAME=LABEL[,NAME=LABEL...], e.g. voltage_a=FloatIn2,speed_a=FloatIn0"
_WRITE_CHUNK_ROWS = 65536


@dataclass(frozen=True, eq=False)
class Trace:
    """One experiment: row k holds the time (s), the voltage commanded at tick k (V; zeros for a
    motor not driven) and the speed measured at tick k (rad/s), and the ``extra`` columns in file
    order. Every column is a read-only 1-D float64 copy of one length. ``integer_columns``: the
    extras the file held as integers, which :func:`write_trace` writes as such (``100``)."""

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
        return getattr(self, f"voltage_{_motor(motor)}")

    def speed(self, motor: str) -> np.ndarray:
        return getattr(self, f"speed_{_motor(motor)}")

    def column(self, name: str) -> np.ndarray:
        """A required or extra column by name (InputError listing the columns if none)."""
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
        """The median time step (s); InputError below two ticks."""
        if len(self) < 2:
            which = f"{self.source} has" if self.source else "has"  # which of several files
            raise InputError(
                f"a trace needs two ticks or more to have a period; {which} {len(self)}"
            )
        return float(np.median(np.diff(self.time_s)))

    @classmethod
    def from_columns(
        cls,
        columns: Mapping[str, ArrayLike],
        source: str | None = None,
        integer_columns: Collection[str] = (),
    ) -> Trace:
        """A trace from all of :data:`REQUIRED_COLUMNS` and any extras (in the mapping's order)."""
        missing = [name for name in REQUIRED_COLUMNS if name not in columns]
        if missing:
            raise InputError(
                f"missing required column(s) {', '.join(missing)}; a trace needs "
                f"{', '.join(REQUIRED_COLUMNS)} (got {', '.join(columns) or 'none'})"
            )
        extra = dict(cast("Mapping[str, np.ndarray]", columns))
        required = {name: extra.pop(name) for name in REQUIRED_COLUMNS}
        return cls(
            **required, extra=extra, source=source, integer_columns=frozenset(integer_columns)
        )


def _as_column(name: str, values: ArrayLike) -> np.ndarray:
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
    """A ``--map`` text, ``NAME=LABEL[,...]``, as trace column → QRC label or CSV header.

    NAME is a required column or any identifier (an extra); a near miss of a required one
    (``speed_A``), a bad item or a name given twice is an InputError.
    """
    mapping: dict[str, str] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
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
    """Write a trace as CSV, creating parent folders; it reads back bit for bit.

    Each value is the shortest text of its float64; ``integer_columns`` (default
    ``trace.integer_columns``) are written without a fraction. What :func:`read_trace` would
    refuse (no ticks, values not finite, time not increasing) is an InputError here.
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
    with writing(path), path.open("w", encoding="utf-8", newline="") as file:
        writer = csv.writer(file, lineterminator="\n")  # str of a Python float: shortest exact
        writer.writerow(columns)
        for start in range(0, len(data), _WRITE_CHUNK_ROWS):
            block = data[start : start + _WRITE_CHUNK_ROWS].tolist()
            if whole:
                for row in block:
                    for j in whole:
                        row[j] = int(row[j])
            writer.writerows(block)


@dataclass(frozen=True)
class TraceMeta:
    """What a trace's meta file says ('' where not known; ``controller`` and ``model`` are a
    run's files as absolute paths, what a smoother of the trace needs)."""

    plant: str
    loop_delay_ticks: int | None
    command: str = ""
    controller: str = ""
    model: str = ""
    created: str = ""
    path: Path | None = None


def meta_path(trace_path: str | Path) -> Path:
    """The meta file of a trace: ``logs/ground.csv`` → ``logs/ground.meta.toml``."""
    path = Path(trace_path)
    return path.with_name(path.stem + ".meta.toml")


def write_trace_meta(
    trace_path: str | Path,
    *,
    plant: str,
    loop_delay_ticks: int | None,
    command: str = "",
    controller: str | Path | None = None,
    model: str | Path | None = None,
) -> Path:
    """Write the meta file beside the trace ``trace_path`` (which need not exist yet)."""
    if loop_delay_ticks is not None and int(loop_delay_ticks) < 0:
        raise InputError(f"loop_delay_ticks must be >= 0 ticks, got {loop_delay_ticks}")
    doc: dict[str, Any] = {"format": TRACE_META_FORMAT, "plant": plant}
    if loop_delay_ticks is not None:
        doc["loop_delay_ticks"] = int(loop_delay_ticks)
    files = {"controller": controller, "model": model}
    doc |= {"command": command} if command else {}
    doc |= {k: str(Path(v).resolve()) for k, v in files.items() if v is not None}
    doc["created"] = datetime.now(UTC).isoformat(timespec="seconds")
    path = meta_path(trace_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        "# cartctl: the loop the trace beside this file was recorded in\n" + tomli_w.dumps(doc),
        encoding="utf-8",
    )
    return path


def read_trace_meta(trace_path: str | Path) -> TraceMeta | None:
    """The meta file of the trace ``trace_path``, or None when it has none."""
    path = meta_path(trace_path)
    if not path.is_file():
        return None
    doc = read_toml(path, "trace meta file")
    fmt = doc.get("format", TRACE_META_FORMAT)
    if fmt != TRACE_META_FORMAT:
        raise DataFileError(path, f"unknown format {fmt!r}; expected {TRACE_META_FORMAT!r}")
    texts = {k: str(doc.get(k, "")) for k in ("command", "controller", "model", "created")}
    plant = str(doc.get("plant", "unknown"))
    return TraceMeta(plant, read_loop_delay(doc, path), **texts, path=path)


def agreed_loop_delay(metas: Mapping[str, TraceMeta | None]) -> int | None:
    """The one loop delay of the traces that know theirs (None if none does); InputError when
    two differ, as one model is for one loop."""
    known = {
        p: m.loop_delay_ticks for p, m in metas.items() if m and m.loop_delay_ticks is not None
    }
    if len(set(known.values())) > 1:
        shown = ", ".join(f"{p}: {d}" for p, d in known.items())
        raise InputError(
            f"the traces were recorded in loops with different delays ({shown} tick(s), from "
            "their .meta.toml files); identify the data of one loop at a time"
        )
    return next(iter(known.values()), None)


def loop_delay_of(trace_paths: Sequence[str | Path]) -> int | None:
    """The loop delay the traces were recorded in, from their meta files (:func:`agreed_loop_delay`)."""
    return agreed_loop_delay({str(p): read_trace_meta(p) for p in trace_paths})
