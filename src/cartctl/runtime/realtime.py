"""Real-time scheduling for the loop's thread (SCHED_FIFO, locked memory) and a paused collector.

A SCHED_FIFO thread preempts every normal thread on its core, removing a sleeping loop's
millisecond wake-up outliers; it needs root, CAP_SYS_NICE or an ``rtprio`` limit, and is set for
the calling thread only, with SCHED_RESET_ON_FORK (a Rerun viewer started later runs normally).
``mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT)`` is tried only where the locked-memory limit
cannot make later allocations fail (root, or an unlimited RLIMIT_MEMLOCK). A full garbage
collection walks every object the process holds (milliseconds after numpy, scipy and the Rerun
SDK); the tick makes no reference cycles, so :func:`gc_paused` keeps the collector out.
"""

from __future__ import annotations

import ctypes
import gc
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from typing import Any

from cartctl.errors import InputError

try:
    import resource
except ImportError:  # not on every platform
    resource = None  # type: ignore[assignment]

_MCL_CURRENT, _MCL_FUTURE, _MCL_ONFAULT = 1, 2, 4  # <sys/mman.h> on Linux


_saved: dict[str, int] = {}  # policy, priority and locked to go back to (the first enable's)


def _lock_memory() -> str:
    """'' once mlockall succeeded, else why not."""
    if resource is None:
        return "no resource limits on this platform"
    soft, _hard = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    if os.geteuid() != 0 and soft != resource.RLIM_INFINITY:
        return f"RLIMIT_MEMLOCK is {soft} bytes and not root"
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE | _MCL_ONFAULT) != 0:
            return f"mlockall: {os.strerror(ctypes.get_errno())}"
    except (OSError, AttributeError) as exc:
        return f"mlockall unavailable: {exc}"
    return ""


def enable_realtime(priority: int = 50, *, lock_memory: bool = True) -> str:
    """Switch the calling thread (the executor's) to SCHED_FIFO at ``priority`` and lock memory,
    as far as the OS permits; the line returned says what was obtained (never raises because the
    OS said no; InputError for a priority outside its range). At or below 50, the priority of
    interrupt threads on PREEMPT_RT kernels, the kernel's work stays ahead.
    """
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
    # what to undo is noted before each change: a stop signal raised right after one still
    # finds it (restore)
    first = not _saved
    if first:
        _saved.update(policy=policy, priority=current, locked=0)
    try:
        setscheduler(
            0, os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0), os.sched_param(priority)
        )
    except OSError as exc:
        if first:
            _saved.clear()
        return f"normal scheduling: SCHED_FIFO not permitted ({exc.strerror or exc})"
    text = f"SCHED_FIFO priority {priority}"
    if not lock_memory:
        return text
    if not _saved["locked"]:
        _saved["locked"] = 1
        why = _lock_memory()
        if why:
            _saved["locked"] = 0
            return f"{text}, memory not locked ({why})"
    return text + ", memory locked"


def restore() -> None:
    """Back to the state from before :func:`enable_realtime` (same thread); never raises."""
    saved = dict(_saved)
    _saved.clear()
    if not saved:
        return
    with suppress(OSError, AttributeError):
        os.sched_setscheduler(0, saved["policy"], os.sched_param(saved["priority"]))
    if saved["locked"]:
        with suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).munlockall()


@contextmanager
def realtime_scheduling(priority: int = 50, *, lock_memory: bool = True) -> Iterator[str]:
    """:func:`enable_realtime` for the ``with`` block (yielding its line), then :func:`restore`."""
    try:
        yield enable_realtime(priority, lock_memory=lock_memory)
    finally:
        restore()


@contextmanager
def gc_paused(*, collect_new: bool = False, quick_gil: bool = False) -> Iterator[None]:
    """Within the block: one collection first, the survivors frozen (:func:`gc.freeze`) and
    automatic collection off. ``collect_new``: keep collecting what the block allocates (a short
    walk), for loops that may run for hours (``cartctl monitor``). ``quick_gil``: any other thread
    hands the GIL back within 0.1 ms too (:func:`sys.setswitchinterval`), for a loop on a cart.
    """
    was_enabled, switch_s = gc.isenabled(), sys.getswitchinterval()
    gc.collect()
    try:  # a stop signal raised right after the freeze or the switch still undoes them
        if quick_gil:
            sys.setswitchinterval(1e-4)
        gc.freeze()
        if not collect_new:
            gc.disable()
        yield
    finally:
        if quick_gil:  # only its own: a round trip of another's 1e-4 gives 99 µs
            sys.setswitchinterval(switch_s)
        gc.unfreeze()
        if was_enabled:
            gc.enable()


def one_blas_thread() -> Any:
    """BLAS (OpenBLAS under numpy and SciPy) on one thread, through threadpoolctl: from this call
    on, or within a ``with`` block (the previous setting restored after it). cartctl's matrices
    are a few states wide; on a few cores a second thread only spins. Covers the libraries loaded
    by then: a process sets ``OPENBLAS_NUM_THREADS`` before numpy loads for the rest."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")
