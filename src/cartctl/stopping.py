"""Stop signals: SIGINT, SIGTERM and SIGHUP all end a command through its shutdown path.

Python turns only SIGINT (Ctrl-C) into an exception; SIGTERM (``kill``, ``systemctl stop``,
``timeout``) and SIGHUP (a closing terminal) would end the process on the spot, with the motors at
the last voltage and the files cut short. :func:`install` makes all three raise
:class:`~cartctl.errors.Interrupted` in the main thread, which the commands catch like Ctrl-C: zero
volts out, files closed, summary printed, exit code 128 + the signal's number (130, 143, 129).

Only the first signal interrupts. Any later one, while the shutdown runs, is absorbed (a second
Ctrl-C in impatience must not cut the shutdown short); so is any signal inside :func:`deferred`.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

from cartctl.errors import Interrupted

__all__ = ["STOP_SIGNALS", "deferred", "exit_code", "ignore", "install", "received", "restore"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

_first: int | None = None
_deferred = 0


def _handler(signum: int, frame: Any) -> None:
    global _first
    if _first is not None or _deferred:  # the shutdown is under way: let it finish
        if _first is None:
            _first = signum
        return
    _first = signum
    raise Interrupted(signum)


def install() -> dict[int, Any]:
    """Route the stop signals to :class:`~cartctl.errors.Interrupted` (main thread only).

    Returns the handlers it replaced, for :func:`restore`.
    """
    global _first, _deferred
    _first, _deferred = None, 0
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {signum: signal.signal(signum, _handler) for signum in STOP_SIGNALS}


def restore(previous: dict[int, Any]) -> None:
    """Put back the handlers :func:`install` replaced."""
    for signum, handler in previous.items():
        signal.signal(signum, handler)


def ignore() -> None:
    """Ignore the stop signals from now on: for the exit after a stop signal.

    An ignored signal stays ignored while the interpreter finalises (a handler of ours would be
    reset to the default there, and a late second signal would then kill the process).
    """
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            signal.signal(signum, signal.SIG_IGN)


def received() -> int | None:
    """The first stop signal received since :func:`install`, or None."""
    return _first


def exit_code(default: int = 130) -> int:
    """128 + the first stop signal's number, or ``default`` when none came (a plain Ctrl-C)."""
    return default if _first is None else 128 + _first


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Within the block, stop signals are noted (:func:`received`) but raise nothing."""
    global _deferred
    _deferred += 1
    try:
        yield
    finally:
        _deferred -= 1
