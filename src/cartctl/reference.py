"""Speed references for the loop, from a short text spec (``cartctl run --reference``).

Specs (speeds in rad/s, times in s):

- ``step:A[:DELAY]``: 0 until DELAY (>= 0, default 0.5 s), then A.
- ``square:A:PERIOD``: +A for half a period, −A for the other half, repeated (starts at +A).
- ``ramp:SLOPE[:LIMIT]``: SLOPE rad/s per second from 0, held at ±LIMIT when given.
- ``const:A``: A throughout.
- ``file:PATH``: a CSV with ``time_s`` and ``reference`` (or ``reference_a``/``reference_b``)
  columns, linearly interpolated on the tick grid and held after its end.
"""

from __future__ import annotations

import csv
import functools
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import PERIOD_S
from cartctl.choices import FORMS
from cartctl.errors import DataFileError, InputError, MissingFileError


def _numbers(spec: str, parts: list[str], low: int, high: int) -> list[float]:
    if not low <= len(parts) <= high:
        raise InputError(f"reference '{spec}' has the wrong number of fields; expected {FORMS}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise InputError(
            f"reference '{spec}': the fields must be numbers; expected {FORMS}"
        ) from None
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"reference '{spec}': the fields must be finite numbers")
    return values


@functools.lru_cache(maxsize=8)
def _read_reference_file(
    path_text: str, mtime_ns: int, motor: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The (time, reference) points of a reference file, read once per file version."""
    path = Path(path_text)
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:  # -sig: a BOM is no column name
            rows = list(csv.reader(f))
    except UnicodeDecodeError as err:
        raise DataFileError(path, f"not UTF-8 text (byte {err.start}); expected CSV") from None
    if len(rows) < 2:
        raise DataFileError(path, "a reference file needs a header and at least one row")
    header = [h.strip() for h in rows[0]]
    name = f"reference_{motor}" if f"reference_{motor}" in header else "reference"
    if "time_s" not in header or name not in header:
        raise DataFileError(
            path,
            f"needs columns time_s and reference (or reference_{motor}); has {', '.join(header)}",
        )
    it, ir = header.index("time_s"), header.index(name)
    try:
        t, r = np.array([(float(row[it]), float(row[ir])) for row in rows[1:]]).reshape(-1, 2).T
    except (ValueError, IndexError):
        raise DataFileError(
            path, "every row needs numbers in time_s and the reference column"
        ) from None
    if not (np.isfinite(t).all() and np.isfinite(r).all()) or np.any(np.diff(t) <= 0):
        raise DataFileError(path, "time_s must increase and the values be finite")
    t.setflags(write=False)
    r.setflags(write=False)
    return t, r


def reference_signal(
    spec: str, n_ticks: int, period_s: float = PERIOD_S, motor: str = "a", *, start_tick: int = 0
) -> NDArray[np.float64]:
    """The reference (rad/s) of a spec at ticks ``start_tick`` … ``start_tick + n_ticks − 1``."""
    kind, _, rest = spec.partition(":")
    parts = rest.split(":") if rest else []
    t = (start_tick + np.arange(n_ticks, dtype=np.float64)) * period_s
    if kind == "step":
        amp, *delay = _numbers(spec, parts, 1, 2)
        if delay and delay[0] < 0.0:  # the run starts at 0 s
            raise InputError(
                f"reference '{spec}': the step's delay must be >= 0 s, got {delay[0]:g}"
            )
        return np.where(t >= (delay[0] if delay else 0.5) - 1e-12, amp, 0.0)
    if kind == "square":
        amp, period = _numbers(spec, parts, 2, 2)
        if period <= 2 * period_s:
            raise InputError(f"reference '{spec}': the period must be longer than two ticks")
        return np.where((t % period) < period / 2, amp, -amp)
    if kind == "ramp":
        slope, *limit = _numbers(spec, parts, 1, 2)
        return np.clip(slope * t, -abs(limit[0]), abs(limit[0])) if limit else slope * t
    if kind == "const":
        (amp,) = _numbers(spec, parts, 1, 1)
        return np.full(n_ticks, amp)
    if kind == "file":
        path = Path(rest)
        if path.is_dir():
            raise DataFileError(path, "is a directory; expected a reference file (CSV)")
        if not path.is_file():
            raise MissingFileError(path, "reference file")
        return np.interp(t, *_read_reference_file(str(path), path.stat().st_mtime_ns, motor))
    raise InputError(f"unknown reference '{spec}'; expected {FORMS}")


def check_reference(spec: str, option: str = "--reference", period_s: float = PERIOD_S) -> str:
    """``spec`` if it names a reference (a file one is read); else one line naming ``option``."""
    if not isinstance(spec, str):  # (from Python: the API)
        raise InputError(f"{option}: unknown reference {spec!r}; expected {FORMS}")
    try:
        reference_signal(spec, 1, period_s)
    except InputError as exc:
        raise InputError(f"{option}: {exc}") from None
    return spec


def check_step_in_run(spec: str, n_ticks: int, period_s: float, option: str) -> None:
    """Refuse a ``step:A:DELAY`` whose DELAY comes after the run's last tick: it never acts."""
    kind, _, rest = spec.partition(":")
    parts, last_s = rest.split(":"), (n_ticks - 1) * period_s
    if kind == "step" and len(parts) == 2 and float(parts[1]) > last_s + 1e-12:
        raise InputError(
            f"{option}: reference '{spec}': the step at {float(parts[1]):g} s comes after the "
            f"run's last tick ({last_s:g} s); give a delay within the run or a longer duration"
        )


class ReferenceSchedule:
    """A reference spec over ``n_ticks`` ticks, computed ``chunk_ticks`` at a time (a minute at
    10 ms) as ``schedule[k]`` reaches them, so a long run never holds all of it. A bad spec fails
    here (the first chunk is computed at once); ``motor`` picks a ``file:`` spec's column."""

    def __init__(
        self, spec: str, n_ticks: int, period_s: float = PERIOD_S, motor: str = "a", *,
        chunk_ticks: int = 6000,
    ) -> None:  # fmt: skip
        if n_ticks < 0 or chunk_ticks < 1:
            raise InputError(f"a reference needs n_ticks >= 0 and chunk_ticks >= 1, got "
                             f"{n_ticks} and {chunk_ticks}")  # fmt: skip
        self.spec, self.n_ticks, self.period_s, self.motor = spec, n_ticks, period_s, motor
        self.chunk_ticks = chunk_ticks
        self._start = 0  # the first tick of the chunk in _values
        self._values: list[float] = self._chunk(0).tolist() if n_ticks else []

    def _chunk(self, start: int) -> NDArray[np.float64]:
        n = min(self.chunk_ticks, self.n_ticks - start)
        return reference_signal(self.spec, n, self.period_s, self.motor, start_tick=start)

    def __len__(self) -> int:
        return self.n_ticks

    def __getitem__(self, k: int) -> float:
        if not 0 <= k < self.n_ticks:
            raise IndexError(f"tick {k} is outside the reference's {self.n_ticks} ticks")
        start = k - k % self.chunk_ticks
        if start != self._start:
            self._start, self._values = start, self._chunk(start).tolist()
        return self._values[k - start]

    def chunks(self) -> Iterator[NDArray[np.float64]]:
        """The whole reference, chunk by chunk (for checks over the run)."""
        for start in range(0, self.n_ticks, self.chunk_ticks):
            yield self._chunk(start)

    def peak_abs(self) -> float:
        """max |reference| over the run (rad/s), 0 for an empty one."""
        return max((float(np.max(np.abs(c))) for c in self.chunks()), default=0.0)
