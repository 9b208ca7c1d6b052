"""The Butterworth prefilter of the report (§3.2): the same low-pass on input and output.

Filtering both signals keeps their ratio, the transfer function, intact in the pass band while
removing high-frequency noise before the ARX fit. The report used a 6th-order filter at 20 Hz,
causal (MATLAB's ``filter``); ``zero_phase`` runs it forward and backward instead (no phase lag,
squared magnitude). scipy.signal designs and runs it, in second-order sections.
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
    """A Butterworth low-pass prefilter.

    Attributes
    ----------
    order : int
        Filter order (the report: 6).
    cutoff_hz : float
        −3 dB frequency (Hz), below the Nyquist frequency (the report: 20 Hz).
    zero_phase : bool
        Forward-backward filtering (no phase lag) instead of the causal filter.
    """

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

    def sos(self, period_s: float) -> NDArray[np.float64]:
        """Second-order sections of the filter at sample period ``period_s``."""
        nyquist_hz = 0.5 / period_s
        if self.cutoff_hz >= nyquist_hz:
            raise InputError(
                f"prefilter cut-off (--cutoff-hz) {self.cutoff_hz:g} Hz must lie below the Nyquist frequency "
                f"{nyquist_hz:g} Hz"
            )
        return signal.butter(self.order, self.cutoff_hz, fs=1.0 / period_s, output="sos")

    def apply(self, x: ArrayLike, period_s: float) -> NDArray[np.float64]:
        """Filter one signal (1-D, one value per tick), starting from rest."""
        sos = self.sos(period_s)
        arr = np.asarray(x, dtype=float)
        if self.zero_phase:
            return signal.sosfiltfilt(sos, arr)
        return signal.sosfilt(sos, arr)

    def describe(self) -> str:
        """For provenance and tables, e.g. 'butter order 6, 20 Hz, causal'."""
        kind = "zero-phase" if self.zero_phase else "causal"
        return f"butter order {self.order}, {self.cutoff_hz:g} Hz, {kind}"
