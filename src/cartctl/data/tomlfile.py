"""Reading the project's TOML files (models, controllers) with errors that name the file and key."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cartctl.errors import DataFileError, MissingFileError

MODEL_FORMAT = "cartctl-model/2"
CONTROLLER_FORMAT = "cartctl-controller/2"
TRACE_META_FORMAT = "cartctl-trace-meta/1"
READABLE: dict[str, tuple[str, ...]] = {
    MODEL_FORMAT: ("cartctl-model/1", MODEL_FORMAT),
    CONTROLLER_FORMAT: ("cartctl-controller/1", CONTROLLER_FORMAT),
    TRACE_META_FORMAT: (TRACE_META_FORMAT,),
}
"""Every version read, by the format written (version 1 has version 2's keys)."""
FORMATS = {
    version: f"a {written.removeprefix('cartctl-').partition('/')[0].replace('-', ' ')} file"
    for written, versions in READABLE.items()
    for version in versions
}
"""What each ``format`` line says a file is, for messages ("a trace meta file")."""


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """Parse a TOML file; a missing file, a folder, an empty file or a CSV is named as such."""
    path = Path(path)
    if path.is_dir():
        raise DataFileError(path, f"is a directory; expected a {what}")
    if not path.is_file():
        raise MissingFileError(path, what)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a BOM (Windows editors) is no statement
    except UnicodeDecodeError:
        raise DataFileError(path, f"is not text; expected a {what} (TOML)") from None
    if not text.strip():
        raise DataFileError(path, f"the file is empty; expected a {what}")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        first = text.lstrip().partition("\n")[0]
        if path.suffix.lower() == ".csv" or ("," in first and "=" not in first):
            raise DataFileError(path, f"is a CSV file, not a {what} (TOML)") from None
        raise DataFileError(path, f"not a valid TOML {what} ({exc})") from None


def check_format(doc: Mapping[str, Any], path: Path, expected: str, what: str) -> str:
    """The ``format`` line if it is a version of ``expected`` this cartctl reads, else a
    DataFileError saying what the file is instead or which versions are read."""
    found = doc.get("format")
    readable = READABLE.get(expected, (expected,))
    if found in readable:
        return str(found)
    if found in FORMATS:
        raise DataFileError(path, f"is {FORMATS[found]}, not a {what}")
    known = " and ".join(repr(v) for v in readable)
    if isinstance(found, str) and found.startswith(expected.rpartition("/")[0] + "/"):
        unread = f"a version this cartctl does not read; it reads {known}"
        raise DataFileError(path, f"has format {found!r}, {unread}")
    shown = "has no 'format' line" if found is None else f"has format {found!r}"
    raise DataFileError(path, f"{shown}; a {what} says format = {expected!r}")


def require(
    table: Mapping[str, Any], key: str, kind: type | tuple[type, ...], path: Path, where: str
) -> Any:
    """``table[key]``, checked to be of ``kind`` (bools are never numbers); else a DataFileError."""
    if key not in table:
        raise DataFileError(path, f"missing key '{key}' in {where}")
    value = table[key]
    if not isinstance(value, kind) or isinstance(value, bool):
        raise DataFileError(path, f"key '{key}' in {where} has the wrong type: {value!r}")
    return value


def read_loop_delay(doc: Mapping[str, Any], path: Path) -> int | None:
    """A model or meta file's ``loop_delay_ticks`` (None when absent), a whole number >= 0."""
    if "loop_delay_ticks" not in doc:
        return None
    delay = require(doc, "loop_delay_ticks", int, path, "the top level")
    if delay < 0:
        raise DataFileError(path, f"loop_delay_ticks must be >= 0 ticks, got {delay}")
    return int(delay)
