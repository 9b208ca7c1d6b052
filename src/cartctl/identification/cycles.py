"""Repeated excitation cycles: the period of an input, and the response averaged over cycles.

The report repeats its ±10 V square wave "to average out the response"; averaging n whole cycles
after the first (the transient from rest) divides the variance of white output noise by n. Also
the argument checks shared with :mod:`~cartctl.identification.etfe`.
"""

from __future__ import annotations

import math
from typing import TypeGuard

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError

PERIOD_RTOL: float = 1e-9
"""Relative tolerance (of max |u|) within which two input samples count as equal."""


def is_whole(value: object) -> TypeGuard[int | np.integer]:
    """True for a Python or numpy integer; False for anything else, booleans included."""
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def check_whole(value: object, name: str) -> int:
    """``value`` as an int when it is a whole number >= 1, else an InputError naming ``name``."""
    if not is_whole(value) or value < 1:
        raise InputError(f"{name} must be a whole number >= 1, got {value!r}")
    return int(value)


def as_sequence(values: ArrayLike, name: str) -> NDArray[np.float64]:
    """A finite 1-D float64 array, or an InputError naming the parameter."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputError(f"{name} must be a sequence of numbers ({err})") from err
    if array.ndim != 1:
        raise InputError(f"{name} must be 1-D (one value per tick), got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name} holds NaN or infinite values; expected finite numbers")
    return array


def as_pair(
    y: ArrayLike,
    u: ArrayLike,
    *,
    names: tuple[str, str] = ("output sequence y", "input sequence u"),
    pair: str = "output and input",
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Output and input of one experiment as finite 1-D arrays of one length (``names`` and
    ``pair`` say how the errors name them)."""
    y_arr, u_arr = as_sequence(y, names[0]), as_sequence(u, names[1])
    if y_arr.size != u_arr.size:
        raise InputError(f"{pair} must be equally long, got {y_arr.size} and {u_arr.size} samples")
    return y_arr, u_arr


def _repeats(u: NDArray[np.float64], p: int, tol: float) -> bool:
    """u[k + p] = u[k] within ``tol`` for every k, checked in growing blocks (early exit)."""
    start, size = 0, 64
    while start < u.size - p:
        stop = min(u.size - p, start + size)
        if np.max(np.abs(u[p + start : p + stop] - u[start:stop])) > tol:
            return False
        start, size = stop, size * 4
    return True


def find_period(u: ArrayLike, *, min_ticks: int = 10) -> int | None:
    """The period of an input (V per tick) that repeats exactly at least twice, in ticks.

    The smallest p ≥ ``min_ticks`` with u[k + p] = u[k] for every k (to :data:`PERIOD_RTOL` of
    max |u|) and len(u) ≥ 2p; a trailing partial period is allowed. None for a sequence that is
    not periodic, is constant or holds fewer than two periods. The report's square wave with 1 s
    holds at 10 ms gives 300.
    """
    u = as_sequence(u, "input sequence u")
    min_ticks = check_whole(min_ticks, "min_ticks")
    if u.size < 2 * min_ticks:
        return None
    tol = PERIOD_RTOL * float(np.max(np.abs(u)))
    if float(np.max(u) - np.min(u)) <= tol:
        return None
    # Candidates must at least match the first sample; the block check rejects the rest quickly.
    lags = np.arange(min_ticks, u.size // 2 + 1)
    for p in lags[np.abs(u[lags] - u[0]) <= tol]:
        if _repeats(u, int(p), tol):
            return int(p)
    return None


def split_cycles(
    y: ArrayLike,
    u: ArrayLike,
    period_ticks: int,
    *,
    skip_first: bool = True,
    min_cycles: int = 2,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Output (rad/s) and input (V) cut into whole cycles, shape (n_cycles, period_ticks).

    A trailing partial cycle is dropped, and the first (the transient from rest) when
    ``skip_first``. Refuses fewer than ``min_cycles`` usable cycles and an input whose cycles
    differ by more than :data:`PERIOD_RTOL` of max |u|.
    """
    y, u = as_pair(y, u)
    p = check_whole(period_ticks, "period_ticks")
    first = 1 if skip_first else 0
    n_whole = y.size // p
    n_cycles = n_whole - first
    if n_cycles < min_cycles:
        skipped = " after dropping the first (transient)" if skip_first else ""
        raise InputError(
            f"needs at least {min_cycles} whole cycle(s){skipped}; {y.size} samples hold "
            f"{n_whole} whole cycle(s) of {p} ticks, so {max(n_cycles, 0)} usable"
        )
    y_cycles = y[first * p : n_whole * p].reshape(n_cycles, p)
    u_cycles = u[first * p : n_whole * p].reshape(n_cycles, p)
    tol = PERIOD_RTOL * max(float(np.max(np.abs(u_cycles))), math.ulp(1.0))
    spread = float(np.max(np.abs(u_cycles - u_cycles[0])))
    if spread > tol:
        raise InputError(
            f"the input does not repeat every {p} ticks (cycles differ by up to {spread:.3g} V); "
            "a periodic input is needed, e.g. with a period from find_period"
        )
    return y_cycles, u_cycles


def average_cycles(
    y: ArrayLike, u: ArrayLike, period_ticks: int, *, skip_first: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """Output and input averaged over whole cycles (:func:`split_cycles`, at least two), and
    the number of cycles averaged."""
    y_cycles, u_cycles = split_cycles(y, u, period_ticks, skip_first=skip_first, min_cycles=2)
    return y_cycles.mean(axis=0), u_cycles.mean(axis=0), int(y_cycles.shape[0])


def periodic_regression_pad(
    y_avg: ArrayLike, u_avg: ArrayLike, lags: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """An averaged cycle with its last ``lags`` samples prepended, for a regression over it.

    An averaged cycle is one period of the periodic steady state, so y[−1] = y[P − 1] and so on.
    With ``lags`` = max(na, nk + nb − 1) (3 for the report's structure), the regression over
    k = lags … lags + P − 1 has exactly P equations, none with made-up initial conditions.
    """
    y, u = as_pair(
        y_avg,
        u_avg,
        names=("averaged output y_avg", "averaged input u_avg"),
        pair="averaged output and input",
    )
    if not is_whole(lags) or not 0 <= lags <= y.size:
        raise InputError(f"lags must be a whole number in 0..{y.size} (the cycle), got {lags!r}")
    n = int(lags)
    return np.concatenate([y[y.size - n :], y]), np.concatenate([u[u.size - n :], u])
