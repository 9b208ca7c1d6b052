"""The superposition test (report §3.3, equation 11, figure 8; ``cartctl linearity``): do the
responses to two steps add up to the response to their sum?

Three step experiments on one motor (say 3 V, 7 V and 10 V) are aligned at their onsets and the
small and large responses added. A linear motor gives zero error; Coulomb friction makes the
summed step run above the added ones (each small step loses the friction once, the sum only once).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cartctl.data.trace import Trace
from cartctl.errors import InputError
from cartctl.measures.stepinfo import StepOnset, final_value, find_step

AMPLITUDE_REL_TOLERANCE = 0.02
"""Small + large may differ from the summed step by this fraction of the summed step ..."""

AMPLITUDE_ABS_TOLERANCE_V = 0.1
"""... or by this many volts, whichever is larger."""

_ROLES = ("small", "large", "sum")
_MIN_ALIGNED_TICKS = 2


def _where(trace: Trace, role: str) -> str:
    return trace.source if trace.source else f"the {role} step trace"


@dataclass(frozen=True, eq=False)
class LinearityResult:
    """The superposition test on one motor: the small, large and sum traces' files, voltage steps
    (V) and onsets (s, each on its own trace's axis); over the span all three cover after their
    onsets, the aligned speeds (rad/s), their sum ``speed_added_rad_s`` = small + large, and
    ``error_rad_s`` = sum − added (positive where the summed step runs faster)."""

    motor: str
    period_s: float
    sources: tuple[str | None, str | None, str | None]
    amplitudes_v: tuple[float, float, float]
    onsets_s: tuple[float, float, float]
    time_s: np.ndarray = field(repr=False)
    speed_small_rad_s: np.ndarray = field(repr=False)
    speed_large_rad_s: np.ndarray = field(repr=False)
    speed_sum_rad_s: np.ndarray = field(repr=False)
    speed_added_rad_s: np.ndarray = field(repr=False)
    error_rad_s: np.ndarray = field(repr=False)

    @property
    def mean_error_rad_s(self) -> float:
        return float(np.mean(self.error_rad_s))

    @property
    def max_abs_error_rad_s(self) -> float:
        return float(np.max(np.abs(self.error_rad_s)))

    @property
    def rms_error_rad_s(self) -> float:
        return float(np.sqrt(np.mean(self.error_rad_s**2)))

    @property
    def steady_state_sum_rad_s(self) -> float:
        """Final value of the summed step's response: mean of its last 5 % (rad/s)."""
        return final_value(self.speed_sum_rad_s)

    @property
    def rms_error_percent(self) -> float | None:
        """RMS error over the RMS of the summed step's response (%); None if that is zero."""
        rms_sum = float(np.sqrt(np.mean(self.speed_sum_rad_s**2)))
        return 100.0 * self.rms_error_rad_s / rms_sum if rms_sum > 0.0 else None

    @property
    def mean_error_percent(self) -> float | None:
        """Mean error over the summed step's steady state (%); None if that is zero."""
        steady = self.steady_state_sum_rad_s
        return 100.0 * self.mean_error_rad_s / steady if steady != 0.0 else None

    def to_dict(self) -> dict[str, Any]:
        return {
            "motor": self.motor,
            "Ts": self.period_s,
            "data": dict(zip(_ROLES, self.sources, strict=True)),
            "amplitudes_v": dict(zip(_ROLES, self.amplitudes_v, strict=True)),
            "onsets_s": dict(zip(_ROLES, self.onsets_s, strict=True)),
            "duration_s": float(self.time_s[-1]),
            "steady_state_sum_rad_s": self.steady_state_sum_rad_s,
            "error_rad_s": {
                "mean": self.mean_error_rad_s,
                "max_abs": self.max_abs_error_rad_s,
                "rms": self.rms_error_rad_s,
            },
            "relative_percent": {
                "rms": self.rms_error_percent,
                "mean": self.mean_error_percent,
            },
        }


def _onset(trace: Trace, motor: str, role: str) -> StepOnset:
    voltage = trace.voltage(motor)
    onset = find_step(voltage)
    if onset is None:
        held = "zero throughout" if not np.any(voltage) else "not a single step from 0 V"
        raise InputError(
            f"motor {motor}'s voltage in {_where(trace, role)} is {held} "
            f"(from {np.min(voltage):g} V to {np.max(voltage):g} V); the superposition test "
            "needs three step experiments on that motor"
        )
    if len(trace) - onset.index < _MIN_ALIGNED_TICKS:
        raise InputError(
            f"{_where(trace, role)} ends {len(trace) - onset.index} tick(s) after its step; "
            "record the response to the step"
        )
    return onset


def linearity(small: Trace, large: Trace, total: Trace, motor: str = "a") -> LinearityResult:
    """Run the superposition test on ``motor``'s responses to steps from 0 V of ``small``,
    ``large`` and their sum (``total``).

    Refuses a trace whose voltage is not one step from 0 V, traces with different ticks, and
    amplitudes that do not add up (beyond 2 % or 0.1 V).
    """
    traces = (small, large, total)
    onsets = tuple(_onset(t, motor, role) for t, role in zip(traces, _ROLES, strict=True))
    periods = [t.period_s for t in traces]
    if max(periods) - min(periods) > 0.01 * min(periods):
        listing = ", ".join(f"{p * 1e3:.4g} ms" for p in periods)
        raise InputError(f"the three traces must share one tick; their time steps are {listing}")
    amp_small, amp_large, amp_sum = (o.amplitude for o in onsets)
    tolerance = max(AMPLITUDE_REL_TOLERANCE * abs(amp_sum), AMPLITUDE_ABS_TOLERANCE_V)
    if abs(amp_small + amp_large - amp_sum) > tolerance:
        raise InputError(
            f"the steps do not add up: {amp_small:g} V + {amp_large:g} V = "
            f"{amp_small + amp_large:g} V, but the sum step is {amp_sum:g} V (tolerance "
            f"{tolerance:.3g} V); give the small, the large and their sum, in that order"
        )
    n = min(len(t) - o.index for t, o in zip(traces, onsets, strict=True))
    speeds = [t.speed(motor)[o.index : o.index + n] for t, o in zip(traces, onsets, strict=True)]
    added = speeds[0] + speeds[1]
    period_s = float(f"{np.median(periods):.9g}")  # 0.01, not 0.010000000000000009
    on_small, on_large, on_sum = (
        float(t.time_s[o.index]) for t, o in zip(traces, onsets, strict=True)
    )
    return LinearityResult(
        motor=motor,
        period_s=period_s,
        sources=(small.source, large.source, total.source),
        amplitudes_v=(amp_small, amp_large, amp_sum),
        onsets_s=(on_small, on_large, on_sum),
        time_s=np.arange(n) * period_s,
        speed_small_rad_s=speeds[0],
        speed_large_rad_s=speeds[1],
        speed_sum_rad_s=speeds[2],
        speed_added_rad_s=added,
        error_rad_s=speeds[2] - added,
    )
