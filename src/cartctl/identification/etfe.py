"""Empirical transfer function estimate (ETFE): the ratio of output to input spectra.

Identification stage, beside the parametric fits: the report compares its ARX models with the
ETFE of the square-wave experiment (its figure 4). With a periodic input (whole cycles, see
:mod:`cartctl.identification.cycles`) the estimate is exact at the excited harmonics on noise-free
data: no leakage and no transient. Without one, the whole record's spectra (or Hann-windowed
segment averages) give an approximation. :func:`model_response` evaluates a model at the same
frequencies. Pure numpy; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError
from cartctl.identification._checks import as_pair, is_whole
from cartctl.identification.cycles import split_cycles
from cartctl.model import ArxModel

__all__ = ["MIN_INPUT_FRACTION", "Etfe", "etfe", "model_response"]

MIN_INPUT_FRACTION: float = 1e-3
"""A frequency bin is excited when its input amplitude |U| exceeds this fraction of max |U|.

The report's square wave has no energy at multiples of three times its fundamental (they are
zero to rounding) and its weakest excited harmonic is about 1 % of the strongest."""


@dataclass(frozen=True, eq=False)
class Etfe:
    """An empirical transfer function: output/input spectrum ratio at the excited frequencies.

    Attributes
    ----------
    freq_hz : ndarray, shape (m,)
        Frequencies of the kept bins (Hz), increasing, in [0, 1 / (2 Ts)].
    response : ndarray of complex, shape (m,)
        Y(f) / U(f) at those frequencies (rad/s per V).
    periodic : bool
        True when estimated from whole periods of a periodic input (coherent sampling: no
        leakage, exact on noise-free data); False for the whole-record or segment estimate.
    n_segments : int
        Periods averaged (periodic), or segments averaged (otherwise; 1 for the whole record).
    period_s : float
        Sample period Ts (s).
    response_std : ndarray, shape (m,), or None
        Standard deviation of ``response`` (rad/s per V) estimated from the cycle-to-cycle spread
        of the output spectrum; None when it cannot be (one period, or non-periodic estimate).
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
        """20 log10 |H| (dB re 1 rad/s per V), shape (m,)."""
        return 20.0 * np.log10(np.abs(self.response))

    def phase_deg(self) -> NDArray[np.float64]:
        """Phase of H in (−180, 180] degrees (not unwrapped), shape (m,)."""
        return np.degrees(np.angle(self.response))

    def to_dict(self) -> dict[str, Any]:
        """JSON form: frequencies, real and imaginary parts, and the estimate's kind."""
        std = None if self.response_std is None else self.response_std.tolist()
        return {
            "freq_hz": self.freq_hz.tolist(),
            "re": self.response.real.tolist(),
            "im": self.response.imag.tolist(),
            "periodic": self.periodic,
            "n_segments": self.n_segments,
            "period_s": self.period_s,
            "response_std": std,
        }


def _excited(power_or_amp: NDArray[np.float64], fraction: float) -> NDArray[np.bool_]:
    peak = float(np.max(power_or_amp)) if power_or_amp.size else 0.0
    if peak <= 0.0:
        raise InputError("the input is zero throughout; an ETFE needs an exciting input")
    return power_or_amp > fraction * peak


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
    """Estimate the frequency response Y(f) / U(f) from one experiment.

    Periodic input (``period_ticks`` given): whole periods only, the first dropped by default
    (transient from rest); the output and input are averaged over the periods (the FFT of the
    mean period is the mean of the periods' FFTs) and the ratio is kept at the excited bins,
    the harmonics k / (P Ts). On noise-free data of a linear system this is exact. With noise,
    averaging n periods divides the noise variance by n, and ``response_std`` estimates the
    remaining standard deviation from the periods' spread. One period after the dropped one is
    enough (then without ``response_std``): exact, but with no averaging.

    Otherwise (``period_ticks`` None): with ``segments`` = 1, the ratio of the FFTs of the whole
    record, without window; with ``segments`` > 1, the record is cut into that many
    Hann-windowed, half-overlapping segments and H = Σ Y U* / Σ |U|² (scipy.signal.csd over
    scipy.signal.welch: the H1 estimate, which
    averages out output noise). Both suffer leakage and the transient from rest, so they are an
    approximation, best where the input is strong.

    In both cases only bins whose input amplitude exceeds ``min_input_fraction`` of the largest
    are kept, so DC is dropped when the input has no mean (the report's square wave).

    Parameters
    ----------
    y : array_like, shape (n,)
        Measured output per tick (rad/s).
    u : array_like, shape (n,)
        Input per tick (V).
    period_s : float
        Sample period Ts (s).
    period_ticks : int, optional
        Period of the input (ticks), e.g. from :func:`~cartctl.identification.cycles.find_period`.
    skip_first : bool, default True
        Periodic case: drop the first period.
    segments : int, default 1
        Non-periodic case: number of Hann-windowed segments to average (1: whole record).
    min_input_fraction : float, default :data:`MIN_INPUT_FRACTION`
        Threshold on |U| relative to its maximum for a bin to be kept, in (0, 1).

    Returns
    -------
    Etfe

    Raises
    ------
    InputError
        Bad sequences or parameters, a zero input, no whole period (after the dropped one), an
        input that does not repeat with ``period_ticks``, or segments shorter than 8 samples.
    """
    if not (isinstance(period_s, int | float) and math.isfinite(period_s) and period_s > 0.0):
        raise InputError(f"period_s must be a positive number of seconds, got {period_s!r}")
    if not 0.0 < min_input_fraction < 1.0:
        raise InputError(f"min_input_fraction must lie in (0, 1), got {min_input_fraction!r}")
    y_arr, u_arr = as_pair(y, u)
    if period_ticks is not None:
        return _periodic(y_arr, u_arr, period_s, period_ticks, skip_first, min_input_fraction)
    if not is_whole(segments) or segments < 1:
        raise InputError(f"segments must be a whole number >= 1, got {segments!r}")
    if segments == 1:
        return _whole_record(y_arr, u_arr, period_s, min_input_fraction)
    return _segment_average(y_arr, u_arr, period_s, int(segments), min_input_fraction)


def _periodic(
    y: NDArray[np.float64],
    u: NDArray[np.float64],
    period_s: float,
    period_ticks: int,
    skip_first: bool,
    fraction: float,
) -> Etfe:
    y_cycles, u_cycles = split_cycles(y, u, period_ticks, skip_first=skip_first, min_cycles=1)
    n, p = y_cycles.shape
    Y_cycles = np.fft.rfft(y_cycles, axis=1)
    Y = Y_cycles.mean(axis=0)
    U = np.fft.rfft(u_cycles[0])
    keep = _excited(np.abs(U), fraction)
    std = None
    if n > 1:  # standard error of the mean output spectrum, from the periods' spread
        y_sem = np.sqrt(np.sum(np.abs(Y_cycles - Y) ** 2, axis=0) / (n - 1) / n)
        std = y_sem[keep] / np.abs(U[keep])
    freq = np.asarray(np.fft.rfftfreq(p, d=period_s), dtype=np.float64)
    return Etfe(
        freq_hz=freq[keep],
        response=Y[keep] / U[keep],
        periodic=True,
        n_segments=n,
        period_s=float(period_s),
        response_std=std,
    )


def _whole_record(
    y: NDArray[np.float64], u: NDArray[np.float64], period_s: float, fraction: float
) -> Etfe:
    if y.size < 8:
        raise InputError(f"an ETFE needs at least 8 samples, got {y.size}")
    Y = np.fft.rfft(y)
    U = np.fft.rfft(u)
    keep = _excited(np.abs(U), fraction)
    freq = np.asarray(np.fft.rfftfreq(y.size, d=period_s), dtype=np.float64)
    return Etfe(freq[keep], Y[keep] / U[keep], False, 1, float(period_s), None)


def _segment_average(
    y: NDArray[np.float64],
    u: NDArray[np.float64],
    period_s: float,
    segments: int,
    fraction: float,
) -> Etfe:
    # ``segments`` half-overlapping windows of length L cover (segments + 1) L / 2 samples.
    length = 2 * y.size // (segments + 1)
    if length < 8:
        raise InputError(
            f"{segments} segments of {y.size} samples are {length} samples long; "
            "use fewer segments (each needs at least 8)"
        )
    hop = length // 2
    spectra = {"fs": 1.0 / period_s, "window": "hann", "nperseg": length, "noverlap": length - hop,
               "detrend": False}  # fmt: skip
    freq, cross = scipy.signal.csd(u, y, **spectra)  # Σ conj(U) Y: the H1 numerator
    _, power = scipy.signal.welch(u, **spectra)  # Σ |U|²
    keep = _excited(np.sqrt(power), fraction)
    return Etfe(freq[keep], cross[keep] / power[keep], False, segments, float(period_s), None)


def model_response(model: ArxModel, freq_hz: ArrayLike) -> NDArray[np.complex128]:
    """The frequency response of a model, H(e^{jωTs}) = num(z) / den(z) with z = e^{j 2π f Ts}.

    Parameters
    ----------
    model : ArxModel
        Discrete model; its ``period_s`` is Ts.
    freq_hz : array_like, shape (m,)
        Frequencies (Hz).

    Returns
    -------
    ndarray of complex, shape (m,)
        H at those frequencies (rad/s per V).
    """
    f = np.asarray(freq_hz, dtype=float)
    z = np.exp(2j * np.pi * f * model.period_s)
    return model.response_at(z)
