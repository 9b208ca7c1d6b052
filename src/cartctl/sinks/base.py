"""The sink interface and the closed-loop trace columns (docs/architecture.md: the trace columns,
and the tick's order: ``write`` inside the tick never blocks, an optional ``idle()`` after it). A
problem that loses no data is reported at ``close``; a file that cannot be written raises
:class:`~cartctl.errors.OutputError` once, and the run stops through its normal stop path."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

from cartctl.data.trace import REQUIRED_COLUMNS

TRACE_COLUMNS: tuple[str, ...] = (
    *REQUIRED_COLUMNS, "tick", "reference_a", "reference_b", "estimate_a", "estimate_b",
    "period_error_us", "compute_us",
)  # fmt: skip
"""Columns of a closed-loop trace, in file order (simulated plants add :data:`TRUE_SPEED_COLUMNS`):
``period_error_us`` is how late tick k started (µs), ``compute_us`` its start to the command (µs)."""

TRUE_SPEED_COLUMNS: tuple[str, ...] = ("true_speed_a", "true_speed_b")


@runtime_checkable
class Sink(Protocol):
    """A consumer of the loop's rows: ``open`` before the first tick, ``write`` one tick's values
    in column order (cheap, non-blocking), ``close`` leaves the files complete."""

    def open(self, columns: Sequence[str]) -> None: ...

    def write(self, row: Sequence[float]) -> None: ...

    def close(self) -> None: ...
