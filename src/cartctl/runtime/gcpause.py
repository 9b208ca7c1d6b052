"""The garbage collector kept out of the loop: everything so far frozen, no collection per tick.

Part of the runtime shell, around :meth:`~cartctl.runtime.executor.PeriodicExecutor.run`. CPython
frees almost everything by reference counting; its cyclic collector only finds cycles, and it runs
when allocations pass a threshold, at whatever tick that happens. A full collection walks every
object the process holds (numpy, scipy, python-control and the Rerun SDK leave hundreds of
thousands after import), which takes milliseconds: a deadline miss. :func:`gc_paused` collects
once before the loop, moves all surviving objects to the permanent generation
(:func:`gc.freeze`, so no later collection walks them) and switches automatic collection off for
the run; the tick makes no reference cycles, so nothing accumulates. Afterwards both are undone.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["gc_paused"]


@contextmanager
def gc_paused(*, collect_new: bool = False) -> Iterator[None]:
    """Within the block: no automatic garbage collection, and the objects from before frozen.

    ``collect_new``: keep collecting, but only what the block allocates (the frozen heap is not
    walked, so a collection stays short), for loops that may run for hours (``cartctl monitor``).
    """
    was_enabled = gc.isenabled()
    gc.collect()
    gc.freeze()
    if not collect_new:
        gc.disable()
    try:
        yield
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()
