"""Speed references for the loop, from a short text spec (``cartctl run --reference``).

Specs (speeds in rad/s, times in s):

- ``step:A[:DELAY]``: 0 until DELAY (default 0.5 s), then A.
- ``square:A:PERIOD``: +A for half a period, −A for the other half, repeated (starts at +A).
- ``ramp:SLOPE[:LIMIT]``: SLOPE rad/s per second from 0, held at ±LIMIT when given.
- ``const:A``: A throughout.
- ``file:PATH``: a CSV with ``time_s`` and ``reference`` (or ``reference_a``/``reference_b``)
  columns, linearly interpolated on the tick grid and held after its end.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cartctl.errors import DataFileError, InputError, MissingFileError

FORMS = "step:A[:DELAY_S], square:A:PERIOD_S, ramp:SLOPE[:LIMIT], const:A or file:PATH"


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


def _from_file(path_text: str, motor: str, time_s: NDArray[np.float64]) -> NDArray[np.float64]:
    path = Path(path_text)
    if not path.is_file():
        raise MissingFileError(path, "reference file")
    with path.open(newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
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
        t = np.array([float(r[it]) for r in rows[1:]])
        r = np.array([float(r[ir]) for r in rows[1:]])
    except (ValueError, IndexError):
        raise DataFileError(
            path, "every row needs numbers in time_s and the reference column"
        ) from None
    if not (np.isfinite(t).all() and np.isfinite(r).all()) or np.any(np.diff(t) <= 0):
        raise DataFileError(path, "time_s must increase and the values be finite")
    return np.interp(time_s, t, r)


def reference_signal(
    spec: str, n_ticks: int, period_s: float = 0.01, motor: str = "a"
) -> NDArray[np.float64]:
    """The reference (rad/s) at each of ``n_ticks`` ticks for a spec (see the module docstring)."""
    kind, _, rest = spec.partition(":")
    parts = rest.split(":") if rest else []
    t = np.arange(n_ticks) * period_s
    if kind == "step":
        values = _numbers(spec, parts, 1, 2)
        amp, delay = values[0], (values[1] if len(values) == 2 else 0.5)
        return np.where(t >= delay - 1e-12, amp, 0.0)
    if kind == "square":
        amp, period = _numbers(spec, parts, 2, 2)
        if period <= 2 * period_s:
            raise InputError(f"reference '{spec}': the period must be longer than two ticks")
        return np.where((t % period) < period / 2, amp, -amp)
    if kind == "ramp":
        values = _numbers(spec, parts, 1, 2)
        out = values[0] * t
        return np.clip(out, -abs(values[1]), abs(values[1])) if len(values) == 2 else out
    if kind == "const":
        (amp,) = _numbers(spec, parts, 1, 1)
        return np.full(n_ticks, amp)
    if kind == "file":
        return _from_file(rest, motor, t)
    raise InputError(f"unknown reference '{spec}'; expected {FORMS}")
