"""Repeated excitation cycles: find the period of an input and average the response over cycles.

Identification stage. The report drives the motors with a +10/0/−10 V square wave repeated
several times "to average out the response"; here that is done explicitly. :func:`find_period`
tells whether an input sequence repeats exactly, :func:`average_cycles` averages the output over
whole cycles after the first (the transient from rest), which divides the variance of white
measurement noise by the number of cycles, and :func:`periodic_regression_pad` prepares an
averaged cycle for a least-squares (ARX) regression. Pure numpy; no I/O.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError
from cartctl.identification._checks import as_pair, as_sequence, is_whole

__all__ = ["average_cycles", "find_period", "periodic_regression_pad", "split_cycles"]

PERIOD_RTOL: float = 1e-9
"""Relative tolerance (of max |u|) within which two input samples count as equal."""

_FIRST_BLOCK = 64


def _repeats(u: NDArray[np.float64], p: int, tol: float) -> bool:
    """True when u[k + p] equals u[k] within ``tol`` for every k (checked in growing blocks)."""
    n_overlap = u.size - p
    start, size = 0, _FIRST_BLOCK
    while start < n_overlap:
        stop = min(n_overlap, start + size)
        if np.max(np.abs(u[p + start : p + stop] - u[start:stop])) > tol:
            return False
        start, size = stop, size * 4
    return True


def find_period(u: ArrayLike, *, min_ticks: int = 10) -> int | None:
    """The period of an input sequence, when it repeats exactly at least twice.

    The period is the smallest p ≥ ``min_ticks`` with u[k + p] = u[k] for every k (to
    :data:`PERIOD_RTOL` of max |u|) and at least two whole periods in the sequence (len(u) ≥ 2p).
    A trailing partial period is allowed. When the fundamental period is shorter than
    ``min_ticks``, its smallest multiple that is not is returned.

    Parameters
    ----------
    u : array_like, shape (n,)
        Input sequence, one value per tick (V).
    min_ticks : int, default 10
        Shortest period considered (ticks).

    Returns
    -------
    int or None
        The period in ticks (the report's square wave with 1 s holds at 10 ms gives 300), or None
        when the sequence is not periodic, is constant (no excitation), or holds fewer than two
        whole periods.

    Raises
    ------
    InputError
        ``u`` is not a finite 1-D sequence, or ``min_ticks`` < 1.
    """
    u = as_sequence(u, "input sequence u")
    if not is_whole(min_ticks) or min_ticks < 1:
        raise InputError(f"min_ticks must be a whole number >= 1, got {min_ticks!r}")
    if u.size < 2 * min_ticks:
        return None
    scale = float(np.max(np.abs(u)))
    tol = PERIOD_RTOL * scale
    if float(np.max(u) - np.min(u)) <= tol:
        return None
    # Candidates must at least match the first sample; the block check rejects the rest quickly.
    lags = np.arange(int(min_ticks), u.size // 2 + 1)
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
    """Cut output and input into whole cycles, one per row, checking that the input repeats.

    A trailing partial cycle is dropped, and so is the first cycle when ``skip_first``.

    Parameters
    ----------
    y : array_like, shape (n,)
        Measured output per tick (rad/s).
    u : array_like, shape (n,)
        Input per tick (V); it must repeat every ``period_ticks`` ticks.
    period_ticks : int
        Cycle length P (ticks).
    skip_first : bool, default True
        Drop the first cycle (transient from rest).
    min_cycles : int, default 2
        Fewest usable cycles accepted.

    Returns
    -------
    y_cycles, u_cycles : ndarray, shape (n_cycles, P)
        Output (rad/s) and input (V) cycles.

    Raises
    ------
    InputError
        Sequences that are not finite, 1-D and equally long, a period below 1, fewer than
        ``min_cycles`` usable cycles, or an input whose cycles differ by more than
        :data:`PERIOD_RTOL` of max |u|.
    """
    y, u = as_pair(y, u)
    if not is_whole(period_ticks) or period_ticks < 1:
        raise InputError(f"period_ticks must be a whole number >= 1, got {period_ticks!r}")
    p = int(period_ticks)
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
    y: ArrayLike,
    u: ArrayLike,
    period_ticks: int,
    *,
    skip_first: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """Average output and input over whole excitation cycles.

    Only whole cycles are used: a trailing partial cycle is dropped, and so is the first cycle
    by default (it holds the transient from rest, so it is not part of the periodic steady
    state). Averaging n cycles divides the variance of white output noise by n.

    Parameters
    ----------
    y, u, period_ticks, skip_first
        As for :func:`split_cycles` (the period e.g. from :func:`find_period`). With
        ``skip_first``, three whole cycles are needed.

    Returns
    -------
    y_avg : ndarray, shape (P,)
        Mean output over the cycles used (rad/s).
    u_avg : ndarray, shape (P,)
        Mean input over the same cycles (V); equal to each of them.
    n_cycles : int
        Number of cycles averaged (≥ 2).

    Raises
    ------
    InputError
        As for :func:`split_cycles`: bad sequences or period, fewer than two usable cycles, or
        an input that does not repeat with that period.
    """
    y_cycles, u_cycles = split_cycles(y, u, period_ticks, skip_first=skip_first, min_cycles=2)
    return y_cycles.mean(axis=0), u_cycles.mean(axis=0), int(y_cycles.shape[0])


def periodic_regression_pad(
    y_avg: ArrayLike, u_avg: ArrayLike, lags: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Prepend the last ``lags`` samples of an averaged cycle, for a regression over the cycle.

    An averaged cycle is one period of the periodic steady state, so the samples before its first
    one are its last ones: y[−1] = y[P − 1] and so on. A regression over the cycle (ARX least
    squares, φ(k) = [−y[k−1], −y[k−2], u[k−2], u[k−3]] for the report's structure) needs those
    past values at its first rows. Pad with ``lags`` = max(na, nk + nb − 1) (3 for the report's
    structure) and regress over k = lags … lags + P − 1 of the padded sequences: exactly P
    equations, none with made-up initial conditions.

    Parameters
    ----------
    y_avg : array_like, shape (P,)
        Averaged output cycle (rad/s).
    u_avg : array_like, shape (P,)
        Averaged input cycle (V).
    lags : int
        Number of past samples the regression reaches back (0 ≤ lags ≤ P).

    Returns
    -------
    y_ext, u_ext : ndarray, shape (lags + P,)
        ``concatenate([x[P − lags:], x])`` for each.

    Raises
    ------
    InputError
        Sequences of different lengths or not finite and 1-D, or ``lags`` outside 0 … P.
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
