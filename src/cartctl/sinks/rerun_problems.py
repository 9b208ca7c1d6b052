"""What goes wrong with a Rerun recording: the SDK's own log lines kept quiet, its failures named.

The SDK writes a ``.rrd`` in a thread of its own and reports a failed write through Rust's logger,
straight onto stderr (coloured ``ERROR``/``WARN`` lines), while the Python side only hears
"File-writer thread shut down prematurely" when it flushes. :func:`quiet_sdk_logs` turns that
logger off for cartctl's process (``RUST_LOG=off`` unless the user set ``RUST_LOG``); it must run
before the SDK is first imported, which the command line does first thing. The sinks then say
what went wrong in one line of their own: :func:`file_failure` reads the SDK's exception (and,
when it does not say, the file system's free space) into the reason an
:class:`~cartctl.errors.OutputError` gives.

This module imports nothing heavy: the command line calls it before parsing.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from cartctl.errors import CartctlError


class RecordingError(CartctlError, RuntimeError):
    """The Rerun recording could not be written completely (raised at ``close`` when strict)."""

    exit_code = 1


class RecordingWarning(UserWarning):
    """The Rerun recording had problems; the run itself went on."""


SDK_LOG_VARIABLE = "RUST_LOG"
"""The variable the SDK's logger takes its filter from, once, when the SDK is loaded."""

_OS_ERROR = re.compile(r"(?:Failed to write: )?([^:]*?) \(os error (\d+)\)")
_FILE_WRITER = ("File-writer", "Failed to write", "file sink", "os error")


_QUIETED: set[str] = set()  # the variables quiet_sdk_logs set (not the user's)


def quiet_sdk_logs() -> None:
    """Turn the Rerun SDK's own log lines off unless the user asked for them (``RUST_LOG``).

    Call before ``rerun`` is imported: the SDK reads the variable once, as it loads.
    """
    if SDK_LOG_VARIABLE not in os.environ:
        os.environ[SDK_LOG_VARIABLE] = "off"
        _QUIETED.add(SDK_LOG_VARIABLE)


def viewer_env() -> dict[str, str]:
    """The environment for a viewer process cartctl starts: the user's own, without the
    ``RUST_LOG=off`` of :func:`quiet_sdk_logs` (a viewer's log explains why it failed)."""
    return {k: v for k, v in os.environ.items() if k not in _QUIETED}


def file_failure(exc: BaseException, path: Path | None) -> str | None:
    """Why the SDK could not write ``path``, from the exception it raised; None when ``exc`` is
    not about the file (a viewer that went away).

    Parameters
    ----------
    exc : BaseException
        What ``set_sinks``, ``flush`` or ``disconnect`` raised.
    path : Path or None
        The recording's file (None: no file, so never a file failure).

    Returns
    -------
    str or None
        The system's words (``No space left on device``), or ``the recording's writer stopped``
        when the SDK does not give them and the disk is not full.
    """
    if path is None:
        return None
    text = str(exc)
    found = _OS_ERROR.search(text)
    if found:
        code = int(found.group(2))
        return os.strerror(code) if code else found.group(1)
    if not any(marker in text for marker in _FILE_WRITER):
        return None
    return "No space left on device" if _disk_full(path) else "the recording's writer stopped"


def _disk_full(path: Path) -> bool:
    """True when the file system holding ``path`` has no block left for an ordinary user."""
    try:
        stats = os.statvfs(path if path.exists() else path.parent)
    except OSError:
        return False
    return stats.f_bavail == 0
