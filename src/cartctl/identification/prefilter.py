"""The report's Butterworth prefilter (§3.2): one low-pass on input and output before the fit.

Filtering both keeps their ratio, the transfer function, in the pass band while removing noise.
The report: 6th order at 20 Hz, causal (MATLAB's ``filter``); ``zero_phase`` runs it forward and
backward instead (no phase lag, squared magnitude). Second-order sections from scipy.signal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from cartctl.errors import InputError


@dataclass(frozen=True)
class Prefilter:
    """A Butterworth low-pass of ``order`` (1..12) with its −3 dB point at ``cutoff_hz`` (Hz)."""

    order: int = 6
    cutoff_hz: float = 20.0
    zero_phase: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.order, int) or not 1 <= self.order <= 12:
            raise InputError(
                f"prefilter order (--order) must be a whole number in 1..12, got {self.order!r}"
            )
        if math.isnan(self.cutoff_hz):
            raise InputError("prefilter cut-off (--cutoff-hz) must be a number, got nan")
        if not (math.isfinite(self.cutoff_hz) and self.cutoff_hz > 0.0):
            raise InputError(
                "prefilter cut-off (--cutoff-hz) must be a positive, finite frequency in Hz, got "
                f"{self.cutoff_hz:g}"
            )

    def apply(self, x: ArrayLike, period_s: float) -> NDArray[np.float64]:
        """Filter one signal (one value per tick of ``period_s`` s), starting from rest."""
        nyquist_hz = 0.5 / period_s
        if self.cutoff_hz >= nyquist_hz:
            raise InputError(
                f"prefilter cut-off (--cutoff-hz) {self.cutoff_hz:g} Hz must lie below the Nyquist frequency "
                f"{nyquist_hz:g} Hz"
            )
        sos = signal.butter(self.order, self.cutoff_hz, fs=1.0 / period_s, output="sos")
        arr = np.asarray(x, dtype=float)
        return signal.sosfiltfilt(sos, arr) if self.zero_phase else signal.sosfilt(sos, arr)

    def describe(self) -> str:
        """For provenance and tables, e.g. 'butter order 6, 20 Hz, causal'."""
        kind = "zero-phase" if self.zero_phase else "causal"
        return f"butter order {self.order}, {self.cutoff_hz:g} Hz, {kind}"
