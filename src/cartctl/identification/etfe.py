"""Empirical transfer function estimate (ETFE): output over input spectrum, as the report's
figure 4 compares with its ARX models; :func:`model_response` evaluates a model at the same
frequencies. Responses are in rad/s per V, frequencies in Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from cartctl.errors import InputError
from cartctl.identification.cycles import as_pair, check_whole, split_cycles
from cartctl.model import ArxModel

MIN_INPUT_FRACTION: float = 1e-3
"""A bin is excited when its |U| exceeds this fraction of max |U|: the report's square wave has
no energy at multiples of three times its fundamental, and its weakest harmonic is about 1 %."""


@dataclass(frozen=True, eq=False)
class Etfe:
    """Y(f) / U(f) at the excited frequencies ``freq_hz`` (increasing, up to 1 / (2 Ts)).

    ``periodic``: from whole periods of a periodic input (no leakage, exact on noise-free data),
    ``n_segments`` of them averaged; otherwise the whole record (1) or that many Hann segments.
    ``response_std`` is the standard deviation of ``response`` from the periods' spread (None
    with one period or a non-periodic estimate). The arrays are read-only.
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

    With ``period_ticks`` (e.g. from :func:`~cartctl.identification.cycles.find_period`): whole
    periods only, the first dropped when ``skip_first``; the periods are averaged and the ratio
    kept at the excited harmonics k / (P Ts). Exact on noise-free data of a linear system;
    averaging n periods divides the noise variance by n.

    Otherwise: with ``segments`` = 1 the ratio of the whole record's FFTs (no window); with more,
    that many half-overlapping Hann segments and H1 = Σ Y U* / Σ |U|² (scipy.signal.csd over
    welch, which averages out output noise). Both suffer leakage and the transient from rest.

    Only bins whose |U| exceeds ``min_input_fraction`` of the largest are kept, so DC is dropped
    for an input without mean.
    """
    if not (isinstance(period_s, int | float) and math.isfinite(period_s) and period_s > 0.0):
        raise InputError(f"period_s must be a positive number of seconds, got {period_s!r}")
    if not 0.0 < min_input_fraction < 1.0:
        raise InputError(f"min_input_fraction must lie in (0, 1), got {min_input_fraction!r}")
    y_arr, u_arr = as_pair(y, u)
    ts = float(period_s)
    if period_ticks is not None:
        y_cyc, u_cyc = split_cycles(y_arr, u_arr, period_ticks, skip_first=skip_first, min_cycles=1)
        n, p = y_cyc.shape
        y_spectra = np.fft.rfft(y_cyc, axis=1)
        y_mean = y_spectra.mean(axis=0)
        u_spec = np.fft.rfft(u_cyc[0])
        keep = _excited(np.abs(u_spec), min_input_fraction)
        std = None
        if n > 1:  # standard error of the mean output spectrum, from the periods' spread
            y_sem = np.sqrt(np.sum(np.abs(y_spectra - y_mean) ** 2, axis=0) / (n - 1) / n)
            std = y_sem[keep] / np.abs(u_spec[keep])
        freq = np.asarray(np.fft.rfftfreq(p, d=ts), dtype=np.float64)
        return Etfe(freq[keep], y_mean[keep] / u_spec[keep], True, n, ts, std)
    segments = check_whole(segments, "segments")
    if segments == 1:
        if y_arr.size < 8:
            raise InputError(f"an ETFE needs at least 8 samples, got {y_arr.size}")
        y_spec, u_spec = np.fft.rfft(y_arr), np.fft.rfft(u_arr)
        keep = _excited(np.abs(u_spec), min_input_fraction)
        freq = np.asarray(np.fft.rfftfreq(y_arr.size, d=ts), dtype=np.float64)
        return Etfe(freq[keep], y_spec[keep] / u_spec[keep], False, 1, ts)
    # ``segments`` half-overlapping windows of length L cover (segments + 1) L / 2 samples.
    length = 2 * y_arr.size // (segments + 1)
    if length < 8:
        raise InputError(
            f"{segments} segments of {y_arr.size} samples are {length} samples long; "
            "use fewer segments (each needs at least 8)"
        )
    spectra: dict[str, Any] = {"fs": 1.0 / ts, "window": "hann", "nperseg": length,
                               "noverlap": length - length // 2, "detrend": False}  # fmt: skip
    freq, cross = scipy.signal.csd(u_arr, y_arr, **spectra)  # Σ conj(U) Y: the H1 numerator
    _, power = scipy.signal.welch(u_arr, **spectra)  # Σ |U|²
    keep = _excited(np.sqrt(power), min_input_fraction)
    return Etfe(freq[keep], cross[keep] / power[keep], False, segments, ts)


def model_response(model: ArxModel, freq_hz: ArrayLike) -> NDArray[np.complex128]:
    """H(z) of ``model`` at z = e^{j 2π f Ts} for the frequencies ``freq_hz`` (Hz)."""
    z = np.exp(2j * np.pi * np.asarray(freq_hz, dtype=float) * model.period_s)
    return model.response_at(z)
