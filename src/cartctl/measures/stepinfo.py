"""Step-response metrics: rise time, overshoot, settling time, steady state (pure numpy).

Shared by identification (``cartctl validate`` compares measured and simulated steps), controller
design (closed-loop step of a design) and run review (the steps of a recorded run). It works on
sampled data of any units; times are in seconds.

Definitions (``target`` is the reference when one is given, else the final value; the step size is
``target − initial``; every level is a fraction of the way from ``initial`` to ``target``, so a
negative step is handled like a positive one):

- final value: the mean of the last 5 % of the samples (at least :data:`MIN_FINAL_SAMPLES`);
- rise time: from the first reach of 10 % to the first reach of 90 %;
- overshoot: how far the response goes beyond the target, in % of the step size (0 if never);
- settling time: from the step onset to the moment the response enters, for good, the band of
  ±2 % of the step size around the target (``settling_band``), or a wider one where a floor in
  response units is given (``settling_floor``: :func:`settling_half_width` with the
  :func:`~cartctl.cart.encoder_quantum_rad_s` of a measured wheel speed, whose resolution is one encoder count
  per tick);
- peak: the sample farthest in the step's direction, its value and its time from the onset.

With a reference, the metrics judge how the response tracks that reference, as
``control.step_info(..., final_output=reference)`` and MATLAB's ``stepinfo(..., 'yfinal', r)`` do:
a response that settles more than 2 % away from its reference has no settling time.

Differences from ``control.step_info`` (python-control 0.10): python-control measures settling and
peak times from t = 0, not from the onset; takes the last sample (not a mean) as the final value
when none is given; counts a sample exactly on the band edge as outside; assumes the response
starts at 0; reports ``abs`` of the peak; and uses the first sample past a level, where this module
by default interpolates linearly between samples (``interpolate=False`` gives python-control's
sample times).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError

__all__ = [
    "MIN_FINAL_SAMPLES",
    "SETTLING_FRACTION",
    "StepInfo",
    "StepOnset",
    "final_value",
    "find_step",
    "first_step",
    "settling_half_width",
    "step_info",
    "step_rows",
]

MIN_FINAL_SAMPLES = 5
"""The final value averages at least this many samples (or all, if there are fewer)."""

FINAL_FRACTION = 0.05
"""The final value averages this fraction of the samples at the end."""

_ROUNDING = 1e-12
"""An excursion past the target below this fraction of the step is rounding, not overshoot."""

RISE_LIMITS = (0.1, 0.9)
"""The rise time runs from the first reach of the first to the first reach of the second fraction."""

SETTLING_FRACTION = 0.02
"""The settling band's half-width as a fraction of the step (the 2 % criterion)."""


def settling_half_width(
    step_size: float, floor: float = 0.0, fraction: float = SETTLING_FRACTION
) -> float:
    """Half-width of the settling band of a step: max(fraction · |step|, floor).

    Parameters
    ----------
    step_size : float
        Target − initial (response units, e.g. rad/s).
    floor : float
        The narrowest band worth judging (response units, ≥ 0): for a measured wheel speed one
        encoder count per tick, :func:`~cartctl.cart.encoder_quantum_rad_s`, so that a small step is not
        judged on the encoder's resolution.
    fraction : float
        Band as a fraction of |step|, in (0, 1).

    Returns
    -------
    float
        The half-width (response units).
    """
    if not 0.0 < fraction < 1.0:
        raise InputError(f"settling band must be a fraction in (0, 1), got {fraction}")
    if not (math.isfinite(floor) and floor >= 0.0):
        raise InputError(f"settling band floor must be a finite number >= 0, got {floor}")
    return max(fraction * abs(step_size), floor)


@dataclass(frozen=True)
class StepInfo:
    """Metrics of one step response.

    Values are in the response's units (rad/s for a wheel speed); times in seconds.

    Attributes
    ----------
    rise_time_s : float or None
        10–90 % rise time (s); None if the response never reaches 90 % of the step.
    settling_time_s : float or None
        2 % settling time from the step onset (s); None if the response is outside the band at
        the last sample (it has not settled within the record).
    overshoot_percent : float
        Excursion beyond the target in % of the step size; 0 when the response never passes it.
    peak_value : float
        The response's value farthest in the step's direction (after the onset).
    peak_time_s : float
        When the peak occurs, from the onset (s).
    steady_state_value : float
        The final value: mean of the last 5 % of the samples.
    steady_state_error : float or None
        Reference − final value; None without a reference.
    initial_value : float
        The value the step starts from.
    step_size : float
        (reference, or final value) − initial; negative for a step down.
    """

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
        """JSON form: the attributes by name (None for an undefined metric)."""
        return asdict(self)


@dataclass(frozen=True)
class StepOnset:
    """Where a signal steps: at sample ``index`` it jumps by ``amplitude`` and then stays.

    Attributes
    ----------
    index : int
        First sample at the new level; 0 when the signal starts at it.
    amplitude : float
        New level − initial level, in the signal's units (V for a voltage); never 0.
    """

    index: int
    amplitude: float


def final_value(response: ArrayLike) -> float:
    """The steady-state value of a response: the mean of its last 5 % of samples.

    Parameters
    ----------
    response : array_like, shape (n,)
        The response, n ≥ 1.

    Returns
    -------
    float
        Mean of the last max(:data:`MIN_FINAL_SAMPLES`, ceil(0.05 n)) samples (all if fewer).
    """
    y = np.asarray(response, dtype=float)
    if y.ndim != 1 or y.size == 0:
        raise InputError(f"a response must be a non-empty 1-D array, got shape {y.shape}")
    count = min(y.size, max(MIN_FINAL_SAMPLES, math.ceil(FINAL_FRACTION * y.size)))
    return float(np.mean(y[-count:]))


def find_step(
    values: ArrayLike, *, initial: float = 0.0, tolerance: float = 1e-6
) -> StepOnset | None:
    """Find a single step: ``initial`` up to some sample, then one other constant level to the end.

    A signal that holds a level other than ``initial`` from its first sample is taken as a step at
    index 0 (a record that starts at the step, from rest at ``initial``).

    Parameters
    ----------
    values : array_like, shape (n,)
        The signal, e.g. a commanded voltage (V).
    initial : float
        The level before the step.
    tolerance : float
        How far a sample may stray from its level and still count as on it (signal units).

    Returns
    -------
    StepOnset or None
        None when the signal is at ``initial`` throughout, or is not one clean step.
    """
    u = np.asarray(values, dtype=float)
    if u.ndim != 1:
        raise InputError(f"a signal must be 1-D, got shape {u.shape}")
    off = np.flatnonzero(np.abs(u - initial) > tolerance)
    if off.size == 0:
        return None
    index = int(off[0])
    level = float(u[index])
    if np.any(np.abs(u[index:] - level) > tolerance):
        return None
    return StepOnset(index, level - initial)


def first_step(reference: NDArray[np.float64], *, initial: float = 0.0) -> tuple[int, int] | None:
    """The first step of a reference (shape (n,)) that starts at ``initial`` (a loop starts at rest).

    Returns ``(start, end)``: ``reference[start:end]`` is its first other level (a change of more
    than 1e-9 ends it); None when it never leaves ``initial`` or holds that level for fewer than
    :data:`MIN_FINAL_SAMPLES` samples.
    """
    moved = np.flatnonzero(np.abs(reference - initial) > 1e-9)
    if moved.size == 0:
        return None
    start = int(moved[0])
    changes = np.flatnonzero(np.abs(np.diff(reference[start:])) > 1e-9)
    end = start + int(changes[0]) + 1 if changes.size else reference.size
    return (start, end) if end - start >= MIN_FINAL_SAMPLES else None


def _crossing(
    time_s: NDArray[np.float64], z: NDArray[np.float64], i: int, level: float, *, interpolate: bool
) -> float:
    """Time at which z reaches ``level`` between samples i − 1 and i (z[i] has reached it)."""
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
    """Overshoot and settling time of N responses at once, as :func:`step_info` defines them.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times from the onset on (s), n ≥ 2.
    z : ndarray, shape (N, n)
        Each response as a fraction of its step: 0 at the initial value, 1 at the target.
    band : float
        The settling band's half-width as a fraction of the step
        (:func:`settling_half_width` / |step|); at 1 or more nothing is left to settle, which
        the caller judges (:func:`step_info` gives None).
    onset_s : float
        When the step is applied (s); settling counts from it.
    interpolate : bool
        As for :func:`step_info`.

    Returns
    -------
    overshoot_percent : ndarray, shape (N,)
        (max z − 1)·100, 0 when within rounding of the target or below it (%).
    settling_time_s : ndarray, shape (N,)
        From the onset to entering the band for good (s); ``inf`` where the last sample is
        outside it (not settled within the record).
    """
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
    """Measure a step response (see the module docstring for the definitions).

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Sample times (s), strictly increasing, n ≥ 2.
    response : array_like, shape (n,)
        The response at those times (any units, e.g. rad/s).
    reference : float, optional
        The value the response should reach; without one, the final value is the target.
    initial : float
        The value the step starts from (response units).
    onset_s : float, optional
        When the step is applied (s); default ``time_s[0]``. Samples before it are ignored, and
        settling and peak times count from it.
    settling_band : float
        Half-width of the settling band as a fraction of the step size (0.02 is 2 %).
    settling_floor : float
        The band is never narrower than this, in response units (default 0: the fraction alone;
        see :func:`settling_half_width`). A step no larger than its band has no settling time (None).
    interpolate : bool
        Interpolate linearly between samples for the rise and settling instants; False takes the
        first sample past the level, as ``control.step_info`` does.

    Returns
    -------
    StepInfo

    Raises
    ------
    InputError
        Arrays of unequal length, not 1-D, shorter than 2, not finite; time not increasing; an
        onset outside the record; a step of size zero; a band not in (0, 1).
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(response, dtype=float)
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
    final = final_value(y)
    target = final if reference is None else float(reference)
    size = target - float(initial)
    if not math.isfinite(size) or size == 0.0:
        what = f"reference {reference}" if reference is not None else f"final value {final:g}"
        raise InputError(
            f"step of size zero: the {what} equals the initial value {initial:g}; a step "
            "response must end away from where it starts"
        )
    k0 = int(np.searchsorted(t, onset, side="left"))
    ts, ys = t[k0:], y[k0:]
    z = (ys - initial) / size  # 0 at the initial value, 1 at the target, whatever the sign

    reached = [np.flatnonzero(z >= level) for level in RISE_LIMITS]
    rise: float | None = None
    if reached[1].size:
        lo, hi = (
            _crossing(ts, z, int(r[0]), level, interpolate=interpolate)
            for r, level in zip(reached, RISE_LIMITS, strict=True)
        )
        rise = hi - lo

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
