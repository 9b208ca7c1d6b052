"""The Rerun viewer (can one open here, where is it, does one listen) and a recording's failures:
the SDK reports a failed ``.rrd`` write through Rust's logger on stderr (which
:func:`quiet_sdk_logs` turns off) while Python only hears "File-writer thread shut down
prematurely"; :func:`file_failure` names it in one line. Light: the command line calls it before
parsing."""

from __future__ import annotations

import os
import re
import shutil
import socket
import sys
import time
from pathlib import Path
from typing import Any, Final
from urllib.parse import urlsplit

from cartctl import stopping
from cartctl.errors import CartctlError


class RecordingError(CartctlError, RuntimeError):
    """The Rerun recording had problems (raised at ``close`` when strict)."""

    exit_code = 1


class RecordingWarning(UserWarning):
    """The Rerun recording had problems; the run itself went on."""


SDK_LOG_VARIABLE = "RUST_LOG"  # read once, when the SDK is loaded

_OS_ERROR = re.compile(r"(?:Failed to write: )?([^:]*?) \(os error (\d+)\)")
_FILE_WRITER = ("File-writer", "Failed to write", "file sink", "os error")


_QUIETED: set[str] = set()  # the variables quiet_sdk_logs set (not the user's)


def quiet_sdk_logs() -> None:
    """``RUST_LOG=off`` unless the user set it; call before ``rerun`` is imported."""
    if SDK_LOG_VARIABLE not in os.environ:
        os.environ[SDK_LOG_VARIABLE] = "off"
        _QUIETED.add(SDK_LOG_VARIABLE)


def viewer_env() -> dict[str, str]:
    """The user's environment for a viewer cartctl starts, without :func:`quiet_sdk_logs`' own."""
    return {k: v for k, v in os.environ.items() if k not in _QUIETED}


def file_failure(exc: BaseException, path: Path | None) -> str | None:
    """Why the SDK could not write ``path``, in the system's words where it gives them (or the
    disk is full), from what it raised; None when ``exc`` is not about the file."""
    if path is None:
        return None
    text = str(exc)
    found = _OS_ERROR.search(text)
    if found:
        code = int(found.group(2))
        return os.strerror(code) if code else found.group(1)
    if not any(marker in text for marker in _FILE_WRITER):
        return None
    try:
        full = os.statvfs(path if path.exists() else path.parent).f_bavail == 0
    except OSError:
        full = False
    return "No space left on device" if full else "the recording's writer stopped"


_RRD_HEADER = 12  # b"RRF2", the SDK's version, the encoding options; then each message's header
_MESSAGE_HEADER = 16  # kind and payload length, u64 little-endian each, then the payload


def cut_to_whole_messages(path: Path) -> None:
    """Cut a ``.rrd`` the SDK stopped writing mid-message (a full disk) back to its last whole
    message: a reader fails on the message cut short, and the recording so far reads without it
    (as a file with no footer). Never raises; a file of another format is left alone."""
    try:
        size = path.stat().st_size
        with path.open("r+b") as f:
            if f.read(4) != b"RRF2":
                return
            end = _RRD_HEADER
            while end + _MESSAGE_HEADER <= size:
                f.seek(end + 8)
                message_end = end + _MESSAGE_HEADER + int.from_bytes(f.read(8), "little")
                if message_end > size:
                    break
                end = message_end
            if end < size:
                f.truncate(end)
    except OSError:
        pass


VIEWER_PORT: Final[int] = 9876
VIEWER_URL: Final[str] = f"rerun+http://127.0.0.1:{VIEWER_PORT}/proxy"  # the native viewer's


def display_available() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def resolve_mode(mode: str) -> str:
    """``--rerun auto`` as it applies here: open a viewer where a display exists, else save."""
    if mode == "auto":
        return "spawn" if display_available() else "save"
    return mode


def viewer_executable() -> str | None:
    """The ``rerun`` viewer next to the running interpreter, else on PATH."""
    name = "rerun.exe" if sys.platform == "win32" else "rerun"
    beside = Path(sys.executable).parent / name
    if beside.is_file():
        return str(beside)
    return shutil.which("rerun")


def viewer_reachable(url: str, timeout_s: float = 0.5) -> bool:
    """Whether something accepts TCP connections at a viewer's ``rerun+http://host:port/proxy``."""
    parts = urlsplit(url.replace("rerun+", "", 1))
    try:
        port = parts.port or (80 if parts.scheme == "http" else 443)
        with socket.create_connection((parts.hostname or "127.0.0.1", port), timeout=timeout_s):
            return True
    except (OSError, ValueError):
        return False


VIEWER_WAIT_S: Final[float] = 5.0  # closing: the longest wait for the viewer's stream to end
_WAIT_AFTER_STOP_S = 0.5  # the same once a stop signal came (Ctrl-C during the wait: at once)


def disconnect(rec: Any, viewer_url: str, path: Path | None) -> None:
    """Flush and close a recording's sinks (its file ``path`` first, then the viewer's stream),
    waiting at most :data:`VIEWER_WAIT_S` (or 0.5 s once a stop signal came). The SDK waits with no
    timeout for a viewer that took the connection but never answers (suspended with Ctrl-Z), in
    ``disconnect()`` and in its exit hook (rerun-io/rerun#12620), and the file waits behind it:
    such a viewer is left to a thread, the hook dropped, the file cut to its whole messages, and
    TimeoutError says so; the SDK's first error is raised."""
    import threading

    import rerun
    from rerun_bindings import finalize_deferred_sinks

    done: list[str] = []
    failed: list[Exception] = []

    def close() -> None:
        try:
            rec.flush(timeout_sec=VIEWER_WAIT_S)
        except Exception as exc:  # and the file and the stream are closed all the same
            failed.append(exc)
        try:
            finalize_deferred_sinks(recording=rec.to_native())  # the file's footer
            done.append("file")
            rec.disconnect()
        except Exception as exc:
            failed.append(exc)

    thread = threading.Thread(target=close, name="rerun-disconnect", daemon=True)
    try:
        thread.start()
    except RuntimeError:  # at the interpreter's exit Python 3.12+ starts no thread: close here
        close()
    start = time.monotonic()
    try:
        while thread.is_alive():
            waited = time.monotonic() - start
            if waited > VIEWER_WAIT_S or (waited > _WAIT_AFTER_STOP_S and stopping.received()):
                raise TimeoutError(_silent(viewer_url, None if done else path))
            thread.join(0.05)
    finally:
        if thread.is_alive():  # the SDK's exit hook would wait for it
            rerun.unregister_shutdown()
            if path is not None and not done:
                cut_to_whole_messages(path)
    if failed:
        raise failed[0]


def _silent(viewer_url: str, path: Path | None) -> str:
    lost = "its stream" if path is None else f"its stream and the end of {path.name}"
    return f"the Rerun viewer at {viewer_url} did not answer: {lost} may be incomplete"
