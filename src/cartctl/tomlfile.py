"""Reading the project's TOML files (models, controllers) with errors that name the file and key."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cartctl.errors import DataFileError, MissingFileError

MODEL_FORMAT = "cartctl-model/1"
"""The ``format`` line of a model file (:mod:`cartctl.modelfile`)."""
CONTROLLER_FORMAT = "cartctl-controller/1"
"""The ``format`` line of a controller file (:mod:`cartctl.design.controllerfile`)."""
TRACE_META_FORMAT = "cartctl-trace-meta/1"
"""The ``format`` line of a trace's meta file (:mod:`cartctl.data.tracemeta`)."""
FORMATS = {MODEL_FORMAT: "a model file", CONTROLLER_FORMAT: "a controller file",
           TRACE_META_FORMAT: "a trace meta file"}  # fmt: skip
"""What each ``format`` line says a file is, for messages about a file given in another's place."""


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """Parse a TOML file; MissingFileError or a DataFileError naming ``what`` the file should be.

    A folder, an empty file and a CSV trace given in a TOML file's place are each named as such.
    """
    path = Path(path)
    if path.is_dir():
        raise DataFileError(path, f"is a directory; expected a {what}")
    if not path.is_file():
        raise MissingFileError(path, what)
    try:
        text = path.read_text(encoding="utf-8")
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


def check_format(doc: Mapping[str, Any], path: Path, expected: str, what: str) -> None:
    """Refuse (DataFileError) a document whose ``format`` line is not ``expected``.

    The message says what the file is instead when its format is a known one (a model given as a
    controller: ``is a model file, not a controller file``).
    """
    found = doc.get("format")
    if found == expected:
        return
    if found in FORMATS:
        raise DataFileError(path, f"is {FORMATS[found]}, not a {what}")
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
