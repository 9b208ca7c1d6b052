"""The garbage collector kept out of the loop: a full collection walks every object the process
holds (hundreds of thousands after numpy, scipy, python-control and the Rerun SDK), milliseconds
at whatever tick it happens; the tick makes no reference cycles, so the loop runs without it."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["gc_paused"]


@contextmanager
def gc_paused(*, collect_new: bool = False) -> Iterator[None]:
    """Within the block: one collection first, the survivors frozen (:func:`gc.freeze`, never
    walked again) and automatic collection off; both undone afterwards.

    ``collect_new``: keep collecting, but only what the block allocates (a short walk), for loops
    that may run for hours (``cartctl monitor``).
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
