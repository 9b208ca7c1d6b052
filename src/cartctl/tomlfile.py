"""Reading the project's TOML files (models, controllers) with errors that name the file and key."""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cartctl.errors import DataFileError, MissingFileError


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """Parse a TOML file; MissingFileError or a DataFileError naming ``what`` the file should be."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, what)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataFileError(path, f"not a valid TOML {what} ({exc})") from None


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
