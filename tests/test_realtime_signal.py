"""A stop signal while the loop's thread switches to real-time scheduling leaves nothing behind.

:func:`cartctl.runtime.realtime.enable_realtime` changed the thread's policy (and locked the
process's memory) before it noted what to undo, so a signal that landed right after the change was
raised before the note: :func:`~cartctl.runtime.realtime.restore` found nothing to undo, and the
thread stayed SCHED_FIFO (the memory locked) for whatever the process did next (the Python API, a
commissioning that runs ``cartctl run`` in process, this test session). The garbage collector's
pause (:func:`~cartctl.runtime.realtime.gc_paused`) did the same. Here the signal is sent from
inside the change itself, with cartctl's handlers installed.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable

import pytest

from cartctl import stopping
from cartctl.runtime import realtime


@pytest.fixture
def fifo() -> None:
    """Skips where this thread may not switch to SCHED_FIFO (then there is nothing to undo)."""
    if not hasattr(os, "sched_setscheduler"):
        pytest.skip("no sched_setscheduler on this platform")
    with realtime.realtime_scheduling(1, lock_memory=False) as text:
        if not text.startswith("SCHED_FIFO"):
            pytest.skip(text)


def _scheduling() -> tuple[int, int]:
    return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority


def _signalling(call: Callable[..., object]) -> Callable[..., object]:
    """``call``, then (the first time) SIGTERM to this process: raised at the caller's next
    instruction."""
    sent: list[bool] = []

    def signalled(*args: object) -> object:
        result = call(*args)
        if not sent:
            sent.append(True)
            os.kill(os.getpid(), signal.SIGTERM)
        return result

    return signalled


def _enable_then_restore(lock_memory: bool = False) -> None:
    """As ``cartctl run`` does: enabled inside the ``try`` whose ``finally`` restores."""
    try:
        realtime.enable_realtime(10, lock_memory=lock_memory)
    finally:
        realtime.restore()


def _within_the_context_manager() -> None:
    with realtime.realtime_scheduling(10, lock_memory=False):
        pass


@pytest.mark.parametrize("enter", [_enable_then_restore, _within_the_context_manager])
def test_a_stop_signal_as_the_policy_changes_is_undone(
    fifo: None, stop_handlers: None, monkeypatch: pytest.MonkeyPatch, enter: Callable[[], None]
) -> None:
    before = _scheduling()
    monkeypatch.setattr(os, "sched_setscheduler", _signalling(os.sched_setscheduler))
    try:
        with pytest.raises(stopping.Interrupted):
            enter()
        after = _scheduling()
    finally:
        monkeypatch.undo()
        os.sched_setscheduler(0, before[0], os.sched_param(before[1]))  # whatever happened
    assert after == before


def test_a_stop_signal_as_the_memory_is_locked_is_undone(
    fifo: None, stop_handlers: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The lock is faked (a real mlockall would hold this test session's memory)."""
    locked: list[bool] = []

    def lock() -> str:
        locked.append(True)
        os.kill(os.getpid(), signal.SIGTERM)
        return ""

    class Libc:
        def munlockall(self) -> int:
            locked.append(False)
            return 0

    monkeypatch.setattr(realtime, "_lock_memory", lock)
    monkeypatch.setattr(realtime.ctypes, "CDLL", lambda *args, **kwargs: Libc())
    with pytest.raises(stopping.Interrupted):
        _enable_then_restore(lock_memory=True)
    assert locked == [True, False]
    assert _scheduling()[0] != os.SCHED_FIFO


@pytest.mark.parametrize("call", ["freeze", "disable"])
def test_a_stop_signal_as_the_collector_is_paused_is_undone(
    stop_handlers: None, monkeypatch: pytest.MonkeyPatch, call: str
) -> None:
    """gc_paused froze the objects and switched the collector off before its ``try``: a signal
    raised right after either left them so for the rest of the process."""
    import gc

    before = (gc.isenabled(), gc.get_freeze_count())
    monkeypatch.setattr(gc, call, _signalling(getattr(gc, call)))
    try:
        with pytest.raises(stopping.Interrupted), realtime.gc_paused():
            pass
        after = (gc.isenabled(), gc.get_freeze_count())
    finally:
        monkeypatch.undo()
        if before[1] == 0:
            gc.unfreeze()
        if before[0]:
            gc.enable()
    assert after == before
