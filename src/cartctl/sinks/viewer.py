"""The Rerun viewer: whether one can open here, where its executable is, whether one listens."""

from __future__ import annotations

import os
import shutil
import socket
import sys
from pathlib import Path
from typing import Final
from urllib.parse import urlsplit

VIEWER_PORT: Final[int] = 9876


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
