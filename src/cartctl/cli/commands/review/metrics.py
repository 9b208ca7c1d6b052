"""``cartctl review RUN.csv [--compare OTHER.csv]``: the run metrics of a run's or a monitor's
trace (a monitor trace has no loop timing: the cart ran its own loop), and of two side by side:
per metric A, B, B − A and, where a ratio means something, (B − A) / |A| in %.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cartctl.choices import is_number
from cartctl.data.columns import MONITOR_LABELS_HINT
from cartctl.data.trace import Trace
from cartctl.errors import DataFileError
from cartctl.measures.numfmt import format_fixed, render_table
from cartctl.sinks.summary import MOTOR_METRICS, SIGNALS, timing_metrics, trace_metrics

TIMING_COLUMNS = ("period_error_us", "compute_us")
TRACKING_COLUMNS = ("reference_a", "speed_a", "voltage_a")


def csv_summary(trace: Trace, path: str | Path) -> dict[str, Any]:
    """The run summary of the CSV trace ``path`` (a run's or a monitor's), with its file name."""
    columns = trace.columns()
    missing = [name for name in TRACKING_COLUMNS if name not in columns]
    if missing == ["reference_a"]:  # speed and voltage named: a trace with no controller in it
        raise DataFileError(
            Path(path),
            "has speed and voltage but no reference_a: review measures how a controller tracks "
            "its reference, and this trace has none (an excitation, or a monitor of the bridge, "
            "which only passes commands on); 'cartctl validate MODEL.toml' and 'cartctl convert' "
            "take it, or give --map reference_a=<column>",
        )
    if missing:
        raise DataFileError(
            Path(path),
            f"review measures tracking and needs {', '.join(TRACKING_COLUMNS)}; missing "
            f"{', '.join(missing)} (the trace has {', '.join(columns)}); a monitor trace names "
            f"them with {MONITOR_LABELS_HINT}, or give --map reference_a=<column>",
        )
    kind = "run" if all(name in columns for name in TIMING_COLUMNS) else "monitor"
    zeros = dict.fromkeys(TIMING_COLUMNS, np.zeros(len(trace)))
    summary = trace_metrics({**zeros, **columns}, trace.period_s)
    if kind == "monitor":  # the cart's own loop: tracking metrics, no loop timing
        empty = np.zeros(0)
        summary.update(timing_metrics(empty, empty, trace.period_s), deadline_misses=None)
    summary["trace_kind"] = kind
    summary["trace"] = str(path)
    return summary


_Row = tuple[tuple[str, ...], str, str, float, int, bool]
_RUN_ROWS: tuple[_Row, ...] = (
    # (key path, label, unit, scale, decimals, relative difference meaningful)
    (("ticks",), "ticks", "", 1.0, 0, True),
    (("duration_s",), "duration", "s", 1.0, 2, True),
    (("deadline_misses",), "deadline misses", "", 1.0, 0, True),
    *(
        ((key, p), f"{name} {p}", "µs", 1.0, 0, True)
        for key, name in (("period_error_us", "period error"), ("compute_us", "compute"))
        for p in ("p50", "p99", "max")
    ),
)


def _rows(a: Mapping[str, Any], b: Mapping[str, Any]) -> list[_Row]:
    """The compared rows, :data:`_RUN_ROWS`' then each motor's (of either summary), followed by
    its smoothed speed's where either summary has them."""
    motors = dict.fromkeys([*a["motors"], *b["motors"]])
    smoothed = {m for m in motors if any("smoothed" in s["motors"].get(m, {}) for s in (a, b))}
    speeds = [(m, sub) for m in motors for sub in ((), ("smoothed",)) if not sub or m in smoothed]
    rows = list(_RUN_ROWS)
    for m, sub in speeds:
        name = " ".join(("motor", m, *sub))
        rows += [
            (("motors", m, *sub, key), f"{name}: {label}", unit, scale, decimals, rel)
            for key, _, label, unit, scale, decimals, rel in MOTOR_METRICS
        ]
    return rows


def _number(value: Any) -> float | None:
    """A finite number (not a bool) as float, else None."""
    return float(value) if is_number(value) and math.isfinite(value) else None


_SKIP = object()


def _slot(value: Any) -> bool:
    """A number's place: a number (not a bool) or None (a metric without a value)."""
    return value is None or is_number(value)


def difference(a: Any, b: Any) -> Any:
    """B − A over the numeric leaves of two summaries (None where either has no number); dicts
    walked key by key (A's keys, then B's), strings, bools and lists left out."""
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        walked = {key: difference(a.get(key), b.get(key)) for key in {**a, **b}}
        return {key: value for key, value in walked.items() if value is not _SKIP}
    if not (_slot(a) and _slot(b)):
        return _SKIP
    x, y = _number(a), _number(b)
    if x is None or y is None:
        return None
    return int(y - x) if isinstance(a, int) and isinstance(b, int) else y - x


def compare(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """``review --compare --json``: both summaries, B − A and (B − A) / |A| in % (for the rows
    where that ratio means something; None when A is 0)."""
    percent: dict[str, Any] = {}
    for path, *_, relative in _rows(a, b):
        if relative:
            *parents, leaf = path
            node = percent
            for key in parents:
                node = node.setdefault(key, {})
            node[leaf] = _percent(_get(a, path), _get(b, path))
    return {
        "runs": [a, b],
        "a": a,
        "b": b,
        "difference": difference(a, b),
        "difference_percent": percent,
    }


def format_compare(a: Mapping[str, Any], b: Mapping[str, Any]) -> str:
    """One table: per metric (per motor) A, B, B − A and (B − A)/|A|, units in the labels."""
    rows: list[tuple[str, ...]] = []
    timed = _real_time(a) or _real_time(b)
    for path, label, unit, scale, decimals, rel in _rows(a, b):
        if not timed and path[0] in ("period_error_us", "compute_us"):
            continue
        x, y = _number(_get(a, path)), _number(_get(b, path))
        diff = None if x is None or y is None else (y - x) * scale
        percent = _percent(x, y) if rel else None
        rows.append(
            (
                f"{label} ({unit})" if unit else label,
                *(_fixed(None if v is None else v * scale, decimals) for v in (x, y)),
                _fixed(diff, decimals, signed=True),
                "—" if percent is None else f"{percent:+.1f} %",
            )
        )
    notes = [_signal_note(a, "A"), _signal_note(b, "B")]
    judged = [SIGNALS[s.get("metrics_signal", "speed")] for s in (a, b)]
    if judged[0] != judged[1]:
        notes.append(f"  tracking on {judged[0]} in A, on {judged[1]} in B")
    lines = [
        f"A: {a.get('trace', 'A')}",
        f"B: {b.get('trace', 'B')}",
        *(note for note in notes if note),
        *render_table(("metric", "A", "B", "B − A", "(B − A)/|A|"), rows, indent="  "),
    ]
    return "\n".join(lines)


def _real_time(summary: Mapping[str, Any]) -> bool:
    """Whether the summary has real-time loop figures (not a simulated clock, not a monitor)."""
    pe, cu = summary.get("period_error_us") or {}, summary.get("compute_us") or {}
    if pe.get("max") is None or cu.get("p99") is None:
        return False
    return not (pe.get("max") == 0.0 and cu.get("p99") == 0.0)


def _signal_note(summary: Mapping[str, Any], name: str) -> str:
    if summary.get("trace_kind") == "monitor":
        return f"  {name} is a monitor trace: no loop timing (the cart ran its own loop)"
    if not _real_time(summary):
        return f"  {name} ran on a simulated clock: no real-time figures"
    return ""


def _get(summary: Mapping[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = summary
    for key in path:
        if not isinstance(value, Mapping):
            return None
        value = value.get(key)
    return value


def _percent(a: Any, b: Any) -> float | None:
    x, y = _number(a), _number(b)
    if x is None or y is None or x == 0.0:
        return None
    return (y - x) / abs(x) * 100.0


def _fixed(value: float | None, decimals: int, *, signed: bool = False) -> str:
    """Fixed decimals per row (one precision for A, B and B − A); B − A signed."""
    text = format_fixed(value, decimals)
    return "+" + text if signed and value is not None and round(value, decimals) > 0.0 else text
