"""The sink interface and the closed-loop trace columns (docs/architecture.md's trace columns).

The loop opens every sink with the column names, writes one row of floats per tick in that order,
and closes every sink on every exit path. ``write`` runs inside the 10 ms tick, before the tick's
compute time is taken: it must never block (buffer, hand off to a thread). A problem that loses no
data (a viewer gone) is recorded and reported at ``close``; a file that cannot be written (a full
disk) raises :class:`~cartctl.errors.OutputError` from the call that met it, once: the loop gives
the other sinks their row, then stops through its normal stop path (a fault of the run). A sink may
also have ``idle()``, which the loop calls after each tick's compute time is taken and before it
waits for the next deadline (or the cart's next frame): work that need not delay the command
(formatting, handing a block to a thread) belongs there.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

from cartctl.data.trace import REQUIRED_COLUMNS

TRACE_COLUMNS: tuple[str, ...] = (
    *REQUIRED_COLUMNS,
    "tick",
    "reference_a",
    "reference_b",
    "estimate_a",
    "estimate_b",
    "period_error_us",
    "compute_us",
)
"""Columns of a closed-loop trace, in file order: every trace's, then the loop's. Simulated
plants add ``true_speed_a``, ``true_speed_b`` after these. Row k: the voltage commanded at tick k
and the speed measured at tick k (as in every trace); ``period_error_us`` is how late tick k
started against its deadline (µs), ``compute_us`` the time from its start to the command being
sent (µs)."""

TRUE_SPEED_COLUMNS: tuple[str, ...] = ("true_speed_a", "true_speed_b")


@runtime_checkable
class Sink(Protocol):
    """A consumer of the loop's rows."""

    def open(self, columns: Sequence[str]) -> None:
        """Prepare for rows with these columns (before the first tick)."""
        ...

    def write(self, row: Sequence[float]) -> None:
        """One tick's values, in column order. Cheap and non-blocking."""
        ...

    def close(self) -> None:
        """Flush everything; the files are complete and valid afterwards."""
        ...
