"""Periodic inputs and the empirical transfer function estimate (ETFE). The report repeats its
±10 V square wave "to average out the response": averaging n whole cycles after the first (the
transient from rest) divides the variance of white output noise by n, and the ETFE (output over
input spectrum, its figure 4) is exact at the harmonics of whole periods on noise-free data.
Responses are in rad/s per V, frequencies in Hz."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from cartctl.choices import is_whole
from cartctl.errors import InputError
from cartctl.model import ArxModel

PERIOD_RTOL: float = 1e-9
"""Relative tolerance (of max |u|) within which two input samples count as equal."""


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
    """The period (ticks) of an input repeating exactly at least twice: the smallest p ≥
    ``min_ticks`` with u[k + p] = u[k] for every k (to :data:`PERIOD_RTOL` of max |u|), a trailing
    partial period allowed; None otherwise (the report's square wave with 1 s holds gives 300)."""
    u = as_sequence(u, "input sequence u")
    min_ticks = check_whole(min_ticks, "min_ticks")
    if u.size < 2 * min_ticks:
        return None
    tol = PERIOD_RTOL * float(np.max(np.abs(u)))
    if float(np.max(u) - np.min(u)) <= tol:
        return None
    # Candidates must at least match the first sample; the block check rejects the rest quickly.
    lags = np.arange(min_ticks, u.size // 2 + 1)
    return next((int(p) for p in lags[np.abs(u[lags] - u[0]) <= tol] if _repeats(u, p, tol)), None)


def split_cycles(
    y: ArrayLike, u: ArrayLike, period_ticks: int, *, skip_first: bool = True, min_cycles: int = 2
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Output (rad/s) and input (V) cut into whole cycles, shape (n_cycles, period_ticks), the
    trailing partial cycle and, with ``skip_first``, the first (the transient from rest) dropped.
    Refuses fewer than ``min_cycles`` cycles and cycles of the input that differ."""
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
    y_cycles, u_cycles = (x[first * p : n_whole * p].reshape(n_cycles, p) for x in (y, u))
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
    """An averaged cycle with its last ``lags`` samples prepended: one period of the periodic
    steady state, y[−1] = y[P − 1] and so on, so with ``lags`` = max(na, nk + nb − 1) the
    regression over the cycle has exactly P equations and no made-up initial conditions."""
    names = ("averaged output y_avg", "averaged input u_avg")
    y, u = as_pair(y_avg, u_avg, names=names, pair="averaged output and input")
    if not is_whole(lags) or not 0 <= lags <= y.size:
        raise InputError(f"lags must be a whole number in 0..{y.size} (the cycle), got {lags!r}")
    n = int(lags)
    return np.concatenate([y[y.size - n :], y]), np.concatenate([u[u.size - n :], u])


MIN_INPUT_FRACTION: float = 1e-3
"""A bin is excited when its |U| exceeds this fraction of max |U|: the report's square wave has
no energy at multiples of three times its fundamental, and its weakest harmonic is about 1 %."""


@dataclass(frozen=True, eq=False)
class Etfe:
    """Y(f) / U(f) at the excited frequencies ``freq_hz`` (increasing, up to 1 / (2 Ts)), from
    ``n_segments`` whole periods (``periodic``), the whole record (1) or Hann segments;
    ``response_std`` from the periods' spread (None with one period or non-periodic). Read-only.
    """

    freq_hz: NDArray[np.float64]
    response: NDArray[np.complex128]
    periodic: bool
    n_segments: int
    period_s: float
    response_std: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        for name in ("freq_hz", "response", "response_std"):
            value = getattr(self, name)
            if value is not None:
                value = np.array(value, dtype=complex if name == "response" else float)
                value.flags.writeable = False
                object.__setattr__(self, name, value)

    def magnitude_db(self) -> NDArray[np.float64]:
        """20 log10 |H| (dB re 1 rad/s per V)."""
        return 20.0 * np.log10(np.abs(self.response))

    def phase_deg(self) -> NDArray[np.float64]:
        """Phase of H in (−180, 180] degrees, not unwrapped."""
        return np.degrees(np.angle(self.response))

    def to_dict(self) -> dict[str, Any]:
        h, std = self.response, self.response_std
        out = {"freq_hz": self.freq_hz.tolist(), "re": h.real.tolist(), "im": h.imag.tolist()}
        out |= {k: getattr(self, k) for k in ("periodic", "n_segments", "period_s")}
        return out | {"response_std": None if std is None else std.tolist()}


def _excited(amplitude: NDArray[np.float64], fraction: float) -> NDArray[np.bool_]:
    peak = float(np.max(amplitude)) if amplitude.size else 0.0
    if peak <= 0.0:
        raise InputError("the input is zero throughout; an ETFE needs an exciting input")
    return amplitude > fraction * peak


def etfe(
    y: ArrayLike,
    u: ArrayLike,
    period_s: float,
    *,
    period_ticks: int | None = None,
    skip_first: bool = True,
    segments: int = 1,
    min_input_fraction: float = MIN_INPUT_FRACTION,
) -> Etfe:
    """Estimate the frequency response Y(f) / U(f) from one experiment (y in rad/s, u in V).

    With ``period_ticks``: the whole periods (the first dropped with ``skip_first``) averaged and
    the ratio kept at the harmonics k / (P Ts), exact on noise-free data. Otherwise the whole
    record's FFTs (``segments`` = 1, no window) or the H1 estimate Σ Y U* / Σ |U|² over that many
    half-overlapping Hann segments; both suffer leakage and the transient from rest. Only bins with
    |U| above ``min_input_fraction`` of the largest are kept.
    """
    if not (isinstance(period_s, int | float) and math.isfinite(period_s) and period_s > 0.0):
        raise InputError(f"period_s must be a positive number of seconds, got {period_s!r}")
    if not 0.0 < min_input_fraction < 1.0:
        raise InputError(f"min_input_fraction must lie in (0, 1), got {min_input_fraction!r}")
    y_arr, u_arr = as_pair(y, u)
    ts = float(period_s)
    periodic = period_ticks is not None
    if not periodic:
        segments = check_whole(segments, "segments")
        if segments == 1 and y_arr.size < 8:
            raise InputError(f"an ETFE needs at least 8 samples, got {y_arr.size}")
    if period_ticks is not None or segments == 1:  # whole periods, or the record as one
        p = y_arr.size if period_ticks is None else period_ticks
        first = skip_first and periodic
        y_cyc, u_cyc = split_cycles(y_arr, u_arr, p, skip_first=first, min_cycles=1)
        n = y_cyc.shape[0]
        y_spectra = np.fft.rfft(y_cyc, axis=1)
        y_mean = y_spectra.mean(axis=0)
        u_spec = np.fft.rfft(u_cyc[0])
        keep = _excited(np.abs(u_spec), min_input_fraction)
        std = None
        if n > 1:  # standard error of the mean output spectrum, from the periods' spread
            y_sem = np.sqrt(np.sum(np.abs(y_spectra - y_mean) ** 2, axis=0) / (n - 1) / n)
            std = y_sem[keep] / np.abs(u_spec[keep])
        freq = np.asarray(np.fft.rfftfreq(p, d=ts), dtype=np.float64)
        return Etfe(freq[keep], y_mean[keep] / u_spec[keep], periodic, n, ts, std)
    # ``segments`` half-overlapping windows of length L cover (segments + 1) L / 2 samples.
    length = 2 * y_arr.size // (segments + 1)
    if length < 8:
        raise InputError(
            f"{segments} segments of {y_arr.size} samples are {length} samples long; "
            "use fewer segments (each needs at least 8)"
        )
    hann = {"window": "hann", "nperseg": length, "noverlap": length - length // 2}
    freq, cross = scipy.signal.csd(u_arr, y_arr, 1.0 / ts, detrend=False, **hann)  # Σ conj(U) Y
    _, power = scipy.signal.welch(u_arr, 1.0 / ts, detrend=False, **hann)  # Σ |U|²
    keep = _excited(np.sqrt(power), min_input_fraction)
    return Etfe(freq[keep], cross[keep] / power[keep], False, segments, ts)


def model_response(model: ArxModel, freq_hz: ArrayLike) -> NDArray[np.complex128]:
    """H(z) of ``model`` at z = e^{j 2π f Ts} for the frequencies ``freq_hz`` (Hz)."""
    z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * model.period_s)
    return model.response_at(z)
