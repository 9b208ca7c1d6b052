"""Margins, crossover and sensitivity peak of a designed loop L = C·G·z^(−extra) (negative
feedback; C the PI's C(z) or C_fb = −U/Y of :mod:`cartctl.design.controller_ss`), from
python-control. Pure: no I/O."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.model import ArxModel


def loop_analysis(
    num: NDArray[np.float64], den: NDArray[np.float64], model: ArxModel, extra_delay_ticks: int
) -> dict[str, Any]:
    """``phase_margin_deg``, ``gain_margin_db`` (None when infinite), ``crossover_hz`` and
    ``sensitivity_peak`` Ms = max|1/(1 + L)| (1/sm, the shortest distance from L to −1; with its
    dB and Hz) of L = C G z^(−extra), C = ``num``/``den`` (descending powers of z), from one call
    of python-control's ``stability_margins``.

    The exact polynomial method is asked for (``margin``'s default grid misses the crossover of
    some well-damped designs), and each crossing it finds is checked on L itself (|L| = 1 within
    1e-6, a phase of −180° within 1e-4 rad: high-order loops give spurious roots) before
    python-control's choice (the smallest |PM|, the GM closest to 1).
    """
    import control

    ts = model.period_s
    loop = (
        control.tf(num, den, ts)
        * model.to_tf()
        * control.tf([1.0], [1.0] + [0.0] * extra_delay_ticks, ts)
    )
    ln, ld = np.squeeze(loop.num[0][0]), np.squeeze(loop.den[0][0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        gms, pms, sms, w180, wcs, wms = control.stability_margins(
            loop, method="poly", returnall=True
        )
    gm, pm, wcp = _checked_margins(ln, ld, ts, gms, pms, w180, wcs)
    ms = 1.0 / float(np.min(sms))
    # python-control searches ωTs in [0, 2π]: a peak above Nyquist is the mirror of one below
    wdt = float(wms[np.argmin(sms)]) * ts % (2.0 * math.pi)
    return {
        "sensitivity_peak": ms,
        "sensitivity_peak_db": 20.0 * math.log10(ms),
        "sensitivity_peak_hz": min(wdt, 2.0 * math.pi - wdt) / (2.0 * math.pi * ts),
        "phase_margin_deg": float(pm) if math.isfinite(pm) else None,
        "gain_margin_db": 20.0 * math.log10(gm) if math.isfinite(gm) and gm > 0 else None,
        "crossover_hz": float(wcp) / (2.0 * math.pi) if math.isfinite(wcp) else None,
    }


def _checked_margins(
    ln: NDArray[np.float64],
    ld: NDArray[np.float64],
    ts: float,
    gms: NDArray[np.float64],
    pms: NDArray[np.float64],
    w180: NDArray[np.float64],
    wcs: NDArray[np.float64],
) -> tuple[float, float, float]:
    """(GM, PM °, crossover rad/s) from the crossings that L(e^{jωTs}) = ln/ld really has."""

    def at(w: float) -> complex:
        z = np.exp(1j * w * ts)
        with np.errstate(divide="ignore", invalid="ignore"):
            return complex(np.polyval(ln, z) / np.polyval(ld, z))

    gain = [
        (g, w)
        for g, w in zip(np.atleast_1d(gms), np.atleast_1d(w180), strict=True)
        if w > 0.0
        and np.isfinite(at(w))
        and at(w).real < 0.0
        and abs(math.atan2(at(w).imag, -at(w).real)) < 1e-4
    ]
    phase = [
        (p, w)
        for p, w in zip(np.atleast_1d(pms), np.atleast_1d(wcs), strict=True)
        if np.isfinite(at(w)) and abs(abs(at(w)) - 1.0) < 1e-6
    ]
    gm = min(gain, key=lambda gw: abs(math.log(gw[0])))[0] if gain else math.inf
    pm, wcp = min(phase, key=lambda pw: abs(pw[0])) if phase else (math.inf, math.nan)
    return float(gm), float(pm), float(wcp)
