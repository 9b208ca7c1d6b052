"""The one exception family of cartctl.

Every error a user can cause derives from :class:`CartctlError` and the matching builtin, so
callers may catch either. The command line prints it as one line on stderr with its exit code.
"""

from __future__ import annotations

from pathlib import Path

from cartctl.stopping import Interrupted

__all__ = ["CartctlError", "DataFileError", "DataWarning", "InputError", "Interrupted",
           "MissingFileError", "PlantError"]  # fmt: skip


class CartctlError(Exception):
    """Base of all errors that cartctl reports to the user; its message is always one line (line
    breaks and other control characters show as escapes, ``\\n``)."""

    exit_code: int = 2

    def __str__(self) -> str:
        text = super().__str__()
        if text.isprintable():  # the usual message: as it is, not rebuilt character by character
            return text
        return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class InputError(CartctlError, ValueError):
    """A bad option, argument or value (wrong range, wrong shape, unknown name)."""


class MissingFileError(CartctlError, FileNotFoundError):
    """A file the user named does not exist."""

    def __init__(self, path: str | Path, what: str = "file") -> None:
        self.path = Path(path)
        super().__init__(f"{what} not found: {self.path}")


class DataFileError(CartctlError, ValueError):
    """A data or model file whose content is wrong: ``PATH[, line N][, column 'C']: PROBLEM``."""

    def __init__(
        self, path: str | Path, problem: str, *, line: int | None = None, column: str | None = None
    ) -> None:
        self.path = Path(path)
        self.problem = problem
        self.line = line
        self.column = column
        where = "" if line is None else f", line {line}"
        where += "" if column is None else f", column '{column}'"
        super().__init__(f"{self.path}{where}: {problem}")


class PlantError(CartctlError, RuntimeError):
    """A plant failed while running (a vanished port, a silent cart, a stalled link)."""

    exit_code = 1


class OutputError(CartctlError, OSError):
    """A file being written stopped short (a full disk): a fault, not a warning.

    ``logs/run.csv is incomplete: No space left on device (after 412 rows)``; ``detail`` is the
    message without the file.
    """

    exit_code = 1

    def __init__(self, path: str | Path, reason: str, *, rows: int | None = None) -> None:
        self.path = Path(path)
        self.reason = reason
        self.rows = rows
        after = "" if rows is None else f" (after {rows} row{'' if rows == 1 else 's'})"
        self.detail = f"{reason}{after}"
        super().__init__(f"{self.path} is incomplete: {self.detail}")


class DataWarning(UserWarning):
    """Data that can be used but looks suspicious (uneven sample spacing, a clipped channel)."""
