"""Real-time scheduling for the loop's thread: SCHED_FIFO and locked memory, where permitted.

Part of the runtime shell: the loop calls :func:`enable_realtime` before its first deadline and
:func:`restore` afterwards (or uses :func:`realtime_scheduling`). Neither ever raises because the
OS said no; the returned line says what was obtained, for the run summary.

On Linux a SCHED_FIFO thread preempts every normal thread on its core, which is what removes the
millisecond wake-up outliers of a sleeping loop. It needs root or CAP_SYS_NICE (or an
``rtprio`` limit). The policy is set for the calling thread only, with SCHED_RESET_ON_FORK, so
processes started later (a Rerun viewer, say) get normal scheduling. Memory is locked with
``mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT)``: pages already in memory, and those faulted
in later, are never swapped out, without prefaulting every mapping. It is tried only where the
locked-memory limit cannot make later allocations fail (root, or an unlimited RLIMIT_MEMLOCK).
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass

from cartctl.errors import InputError

try:
    import resource
except ImportError:  # not on every platform
    resource = None  # type: ignore[assignment]

_MCL_CURRENT, _MCL_FUTURE, _MCL_ONFAULT = 1, 2, 4  # <sys/mman.h> on Linux


@dataclass
class _Saved:
    policy: int
    priority: int
    memory_locked: bool


_saved: _Saved | None = None  # the scheduling to go back to, set by the first enable_realtime


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None, use_errno=True)


def _may_lock_memory() -> tuple[bool, str]:
    if resource is None:
        return False, "no resource limits on this platform"
    soft, _hard = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    if os.geteuid() == 0 or soft == resource.RLIM_INFINITY:
        return True, ""
    return False, f"RLIMIT_MEMLOCK is {soft} bytes and not root"


def _lock_memory() -> str:
    """Try mlockall; return '' on success, else why not."""
    ok, why = _may_lock_memory()
    if not ok:
        return why
    try:
        libc = _libc()
        if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE | _MCL_ONFAULT) != 0:
            err = ctypes.get_errno()
            return f"mlockall: {os.strerror(err)}"
    except (OSError, AttributeError) as exc:
        return f"mlockall unavailable: {exc}"
    return ""


def enable_realtime(priority: int = 50, *, lock_memory: bool = True) -> str:
    """Switch the calling thread to SCHED_FIFO and lock memory, as far as the OS permits.

    Call it from the thread that runs the executor. Never raises because of the OS.

    Parameters
    ----------
    priority : int, default 50
        SCHED_FIFO priority, within the OS's range (1-99 on Linux). Staying at or below 50, the
        priority of interrupt threads on PREEMPT_RT kernels, leaves the kernel's work ahead.
    lock_memory : bool, default True
        Also lock the process's memory (see the module docstring).

    Returns
    -------
    str
        One line: ``"SCHED_FIFO priority 50, memory locked"``, ``"SCHED_FIFO priority 50,
        memory not locked (why)"``, or ``"normal scheduling: SCHED_FIFO not permitted (why)"``.

    Raises
    ------
    InputError
        If ``priority`` is outside the OS's SCHED_FIFO range (a caller's mistake, not the OS's).
    """
    global _saved
    setscheduler = getattr(os, "sched_setscheduler", None)
    if setscheduler is None or not hasattr(os, "SCHED_FIFO"):
        return "normal scheduling: SCHED_FIFO not available on this platform"
    lo, hi = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if isinstance(priority, bool) or not isinstance(priority, int) or not lo <= priority <= hi:
        raise InputError(
            f"SCHED_FIFO priority must be an integer in [{lo}, {hi}], got {priority!r}"
        )
    try:
        policy, current = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    except OSError as exc:
        return f"normal scheduling: cannot read the current policy ({exc})"
    try:
        setscheduler(
            0, os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0), os.sched_param(priority)
        )
    except OSError as exc:
        return f"normal scheduling: SCHED_FIFO not permitted ({exc.strerror or exc})"
    if _saved is None:
        _saved = _Saved(policy, current, memory_locked=False)
    text = f"SCHED_FIFO priority {priority}"
    if not lock_memory:
        return text
    if _saved.memory_locked:
        return text + ", memory locked"
    why = _lock_memory()
    if why:
        return f"{text}, memory not locked ({why})"
    _saved.memory_locked = True
    return text + ", memory locked"


def restore() -> None:
    """Go back to the scheduling and memory state from before :func:`enable_realtime`.

    Call it from the same thread. Does nothing if real-time scheduling was not obtained.
    Never raises.
    """
    global _saved
    saved, _saved = _saved, None
    if saved is None:
        return
    with suppress(OSError, AttributeError):
        os.sched_setscheduler(0, saved.policy, os.sched_param(saved.priority))
    if saved.memory_locked:
        with suppress(OSError, AttributeError):
            _libc().munlockall()


@contextmanager
def realtime_scheduling(priority: int = 50, *, lock_memory: bool = True) -> Iterator[str]:
    """:func:`enable_realtime` for the ``with`` block, then :func:`restore`.

    Yields
    ------
    str
        The description returned by :func:`enable_realtime`.
    """
    description = enable_realtime(priority, lock_memory=lock_memory)
    try:
        yield description
    finally:
        restore()
