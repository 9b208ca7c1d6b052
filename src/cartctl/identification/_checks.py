"""Argument checks shared by the signal-level identification functions (cycles, ETFE).

Each check returns the cleaned value or raises :class:`~cartctl.errors.InputError` with a message
that names the parameter, so the public functions refuse bad input the same way.
"""

from __future__ import annotations

from typing import TypeGuard

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError

__all__ = ["as_pair", "as_sequence", "is_whole"]


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
    """An output and an input sequence of one experiment, checked by :func:`as_sequence`.

    Parameters
    ----------
    y, u : array_like, shape (n,)
        Output and input, one value per tick.
    names : (str, str)
        How the errors name ``y`` and ``u``.
    pair : str
        How the error for sequences of different lengths names the two.

    Returns
    -------
    y, u : ndarray, shape (n,)
        Finite float64 arrays of one length.

    Raises
    ------
    InputError
        A sequence that is not finite and 1-D, or sequences of different lengths.
    """
    y_arr, u_arr = as_sequence(y, names[0]), as_sequence(u, names[1])
    if y_arr.size != u_arr.size:
        raise InputError(f"{pair} must be equally long, got {y_arr.size} and {u_arr.size} samples")
    return y_arr, u_arr


def is_whole(value: object) -> TypeGuard[int | np.integer]:
    """True for a Python or numpy integer; False for anything else, booleans included."""
    return isinstance(value, int | np.integer) and not isinstance(value, bool)
