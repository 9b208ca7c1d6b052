"""Step-response metrics of sampled data (any units; times in s from the onset), shared by
``validate``, ``design``, ``tune`` and the run summary.

The target is the reference when given, else the final value; levels are fractions of the way
from ``initial`` to the target, so a step down is measured like a step up.

- final value: the mean of the last 5 % of the samples from the onset on (at least
  :data:`MIN_FINAL_SAMPLES`);
- rise time: from the first reach of 10 % to the first reach of 90 %;
- overshoot: beyond the target, in % of the step size (0 if never);
- settling time: until the response stays within ±2 % of the step around the target, or within
  ``settling_floor`` where wider (a measured wheel speed: one encoder count per tick,
  :func:`~cartctl.cart.encoder_quantum_rad_s`); a sample on the band edge is inside;
- peak: the sample farthest in the step's direction, and its time.

As ``control.step_info(..., final_output=r)``, but times count from the onset, the final value is a
mean, the response need not start at 0, and level crossings are interpolated between samples
(``interpolate=False`` gives the sample times python-control 0.10 reports)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError

MIN_FINAL_SAMPLES = 5
FINAL_FRACTION = 0.05
RISE_LIMITS = (0.1, 0.9)
SETTLING_FRACTION = 0.02
_ROUNDING = 1e-12  # an excursion past the target below this fraction of the step is rounding


def settling_half_width(
    step_size: float, floor: float = 0.0, fraction: float = SETTLING_FRACTION
) -> float:
    """Half-width of the settling band: max(fraction · |step_size|, floor ≥ 0), in response units,
    for a ``fraction`` in (0, 1)."""
    if not 0.0 < fraction < 1.0:
        raise InputError(f"settling band must be a fraction in (0, 1), got {fraction}")
    if not (math.isfinite(floor) and floor >= 0.0):
        raise InputError(f"settling band floor must be a finite number >= 0, got {floor}")
    return max(fraction * abs(step_size), floor)


@dataclass(frozen=True)
class StepInfo:
    """Metrics of one step response: values in the response's units, times in s from the onset.
    ``rise_time_s`` is None if 90 % is never reached, ``settling_time_s`` if the last sample is
    outside the band; ``steady_state_error`` (reference − final value) is None without a reference;
    ``step_size`` is (reference or final value) − initial, negative for a step down."""

    rise_time_s: float | None
    settling_time_s: float | None
    overshoot_percent: float
    peak_value: float
    peak_time_s: float
    steady_state_value: float
    steady_state_error: float | None
    initial_value: float
    step_size: float

    def to_dict(self) -> dict[str, float | None]:
        return asdict(self)


@dataclass(frozen=True)
class StepOnset:
    """At sample ``index`` a signal jumps by ``amplitude`` (≠ 0, signal units) and then stays."""

    index: int
    amplitude: float


def final_value(response: ArrayLike) -> float:
    """The mean of the last max(:data:`MIN_FINAL_SAMPLES`, ceil(0.05 n)) samples (all if fewer)."""
    y = np.asarray(response, dtype=float)
    if y.ndim != 1 or y.size == 0:
        raise InputError(f"a response must be a non-empty 1-D array, got shape {y.shape}")
    count = min(y.size, max(MIN_FINAL_SAMPLES, math.ceil(FINAL_FRACTION * y.size)))
    return float(np.mean(y[-count:]))


def find_step(values: ArrayLike) -> StepOnset | None:
    """A single step: 0 up to some sample, then one other level (within 1e-6) to the end; a signal
    at another level from sample 0 steps at index 0. None: no step, or not one clean step."""
    u = np.asarray(values, dtype=float)
    if u.ndim != 1:
        raise InputError(f"a signal must be 1-D, got shape {u.shape}")
    off = np.flatnonzero(np.abs(u) > 1e-6)
    if off.size == 0:
        return None
    index = int(off[0])
    level = float(u[index])
    if np.any(np.abs(u[index:] - level) > 1e-6):
        return None
    return StepOnset(index, level)


def first_step(reference: NDArray[np.float64], *, initial: float = 0.0) -> tuple[int, int] | None:
    """``(start, end)`` of the first other level of a reference that starts at ``initial``; None
    when it never leaves it or holds the level for fewer than :data:`MIN_FINAL_SAMPLES` samples."""
    moved = np.flatnonzero(np.abs(reference - initial) > 1e-9)
    if moved.size == 0:
        return None
    start = int(moved[0])
    changes = np.flatnonzero(np.abs(np.diff(reference[start:])) > 1e-9)
    end = start + int(changes[0]) + 1 if changes.size else reference.size
    return (start, end) if end - start >= MIN_FINAL_SAMPLES else None


def _crossing(
    time_s: NDArray[np.float64], z: NDArray[np.float64], level: float, *, interpolate: bool
) -> float | None:
    """When ``z`` first reaches ``level`` (None if never), interpolated from the sample before."""
    reached = np.flatnonzero(z >= level)
    if not reached.size:
        return None
    i = int(reached[0])
    if i == 0 or not interpolate:
        return float(time_s[i])
    frac = (level - z[i - 1]) / (z[i] - z[i - 1])
    return float(time_s[i - 1] + frac * (time_s[i] - time_s[i - 1]))


def step_rows(
    time_s: NDArray[np.float64],
    z: NDArray[np.float64],
    band: float,
    onset_s: float,
    *,
    interpolate: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Overshoot (%) and settling time (s, ``inf`` if not settled) of N responses at once. ``z`` (N,
    n) holds each response as a fraction of its step (0 initial, 1 target) at ``time_s`` (from the
    onset on); ``band`` is the band's half-width as a fraction of the step (at 1 or more nothing is
    left to settle, which the caller judges)."""
    excess = np.max(z, axis=1) - 1.0
    overshoot = np.where(excess <= _ROUNDING, 0.0, excess) * 100.0
    outside = np.abs(z - 1.0) > band
    last = z.shape[1] - 1 - np.argmax(outside[:, ::-1], axis=1)  # the last sample outside
    j = np.minimum(last, z.shape[1] - 2)
    rows = np.arange(z.shape[0])
    zj, zi = z[rows, j], z[rows, j + 1]
    if interpolate:
        edge = np.where(zj > 1.0, 1.0 + band, 1.0 - band)
        with np.errstate(all="ignore"):
            settled = time_s[j] + (edge - zj) / (zi - zj) * (time_s[j + 1] - time_s[j])
    else:
        settled = time_s[j + 1]
    settling = np.where(outside.any(axis=1), settled - onset_s, time_s[0] - onset_s)
    return overshoot, np.where(outside[:, -1], np.inf, settling)


def step_info(
    time_s: ArrayLike,
    response: ArrayLike,
    *,
    reference: float | None = None,
    initial: float = 0.0,
    onset_s: float | None = None,
    settling_band: float = SETTLING_FRACTION,
    settling_floor: float = 0.0,
    interpolate: bool = True,
) -> StepInfo:
    """Measure a step response (definitions in the module docstring) of ``time_s`` strictly
    increasing and ``response``, shape (n,), n ≥ 2, ignoring samples before ``onset_s`` (default
    ``time_s[0]``). The band's half-width is ``settling_band`` of the step, at least
    ``settling_floor``; a step no larger than its band has no settling time. InputError for
    unequal, short or non-finite arrays, time not increasing, an onset outside the record, a step
    of size zero or a band not in (0, 1)."""
    t, y = np.asarray(time_s, dtype=float), np.asarray(response, dtype=float)
    if t.ndim != 1 or y.ndim != 1 or t.shape != y.shape:
        raise InputError(
            f"time and response must be 1-D arrays of equal length, got shapes {t.shape} and "
            f"{y.shape}"
        )
    if t.size < 2:
        raise InputError(f"a step response needs two samples or more, got {t.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise InputError("time and response must hold finite numbers only")
    if np.any(np.diff(t) <= 0.0):
        raise InputError("time must increase from sample to sample")
    settling_half_width(1.0, settling_floor, settling_band)  # the band's arguments, checked
    onset = float(t[0]) if onset_s is None else float(onset_s)
    if not t[0] <= onset <= t[-1]:
        raise InputError(
            f"step onset {onset_s} s lies outside the record ({t[0]:g} s to {t[-1]:g} s)"
        )
    k0 = int(np.searchsorted(t, onset, side="left"))
    ts, ys = t[k0:], y[k0:]
    final = final_value(ys)  # of the response from the onset on, not of the samples before
    target = final if reference is None else float(reference)
    size = target - float(initial)
    if not math.isfinite(size) or size == 0.0:
        what = f"reference {reference}" if reference is not None else f"final value {final:g}"
        raise InputError(
            f"step of size zero: the {what} equals the initial value {initial:g}; a step "
            "response must end away from where it starts"
        )
    z = (ys - initial) / size  # 0 at the initial value, 1 at the target, whatever the sign

    lo, hi = (_crossing(ts, z, level, interpolate=interpolate) for level in RISE_LIMITS)
    rise = None if lo is None or hi is None else hi - lo

    band = settling_half_width(size, settling_floor, settling_band) / abs(size)  # of the step
    overshoot, settled = step_rows(ts, z[None, :], band, onset, interpolate=interpolate)
    # a band that reaches back to the initial value leaves nothing to settle
    settling = None if band >= 1.0 or math.isinf(settled[0]) else float(settled[0])
    i_peak = int(np.argmax(z))
    return StepInfo(
        rise_time_s=rise,
        settling_time_s=settling,
        overshoot_percent=float(overshoot[0]),
        peak_value=float(ys[i_peak]),
        peak_time_s=float(ts[i_peak] - onset),
        steady_state_value=final,
        steady_state_error=None if reference is None else float(reference) - final,
        initial_value=float(initial),
        step_size=size,
    )
