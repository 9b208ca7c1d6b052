"""The linear feedback part of a pole-placement controller, for margins and ``controller_num/den``.

With the steady-state estimator the pole-placement controller is linear time-invariant. Its state
is the predicted estimate x̂[k|k−1] (m states) and the error integral x_i; per tick (the order of
:class:`~cartctl.runtime.statefeedback.StateFeedbackController`)::

    x̂c     = x̂ + L (y − C x̂)
    u      = −K x̂c − K_xi x_i + Kr r          (K on the first K.size states: with the input-
    x̂⁺     = A x̂c + B u                      disturbance state it ends with 1 on b̂)
    x_i⁺   = x_i + Ts (r − y)               (left out when K_xi = 0: it does not reach u)

The loop is broken at the measurement: C_fb(z) = −U(z)/Y(z) with r = 0, so that the open loop is
C_fb(z) G(z) z^(−extra) with negative feedback, as for the PI.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.poles import PolesDesign
from cartctl.model import ArxModel


def feedback_tf_coeffs(design: PolesDesign) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """C_fb(z) = −U/Y as (num, den) in descending powers of z (minimal: common roots cancelled)."""
    import control

    est = design.estimator
    m = est.A.shape[0]
    n = design.K.size
    k_full = np.zeros(m)
    k_full[:n] = design.K
    lc = np.eye(m) - np.outer(est.L, est.C)
    # state s = [x̂ (m), x_i], input y, output u; without K_xi (integral action from the
    # disturbance estimate) x_i does not reach u and is left out: its pole at z = 1 would meet
    # the estimator's own there and not cancel cleanly
    i = m + 1 if design.K_xi != 0.0 else m
    a = np.zeros((i, i))
    a[:m, :m] = est.A @ lc - np.outer(est.B, k_full @ lc)
    b = np.zeros((i, 1))
    b[:m, 0] = est.A @ est.L - est.B * float(k_full @ est.L)
    c = np.zeros((1, i))
    c[0, :m] = -(k_full @ lc)
    if i > m:
        a[:m, m] = -est.B * design.K_xi
        a[m, m] = 1.0
        b[m, 0] = -design.period_s
        c[0, m] = -design.K_xi
    d = np.array([[-float(k_full @ est.L)]])
    # ss2tf then a transfer-function minreal: the state-space minreal needs slycot
    tf = control.ss2tf(control.ss(a, b, -c, -d, design.period_s)).minreal(tol=1e-9)
    num = np.atleast_1d(np.squeeze(tf.num[0][0]))
    den = np.atleast_1d(np.squeeze(tf.den[0][0]))
    return num / den[0], den / den[0]


def loop_analysis(
    num: NDArray[np.float64], den: NDArray[np.float64], model: ArxModel, extra_delay_ticks: int
) -> dict[str, Any]:
    """Margins, crossover and sensitivity peak max|1/(1 + L)| of the open loop L = C G z^(−extra).

    The margins are python-control's ``stability_margins`` with the exact polynomial method:
    ``margin``'s default falls back, for some well-damped low-crossover designs, to a frequency
    grid that misses the crossover. On high-order loops (a pole-placement controller with its
    estimator and a serial loop's delay) the polynomial's roots include spurious crossings, so
    every crossing is checked on L itself (|L| = 1 within 1e-6, or a phase of −180° within 1e-4
    rad) before python-control's choice (the smallest |PM|, the GM closest to 1) is made. The
    sensitivity is sampled at 4001 points up to Nyquist.
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
        gms, pms, _, w180, wcs, _ = control.stability_margins(loop, method="poly", returnall=True)
    gm, pm, wcp = _checked_margins(ln, ld, ts, gms, pms, w180, wcs)
    z = np.exp(2j * np.pi * np.linspace(0.0, 0.5 / ts, 4001) * ts)
    with np.errstate(divide="ignore", invalid="ignore"):  # L has a pole at z = 1 (the integrator)
        sensitivity = np.abs(np.polyval(ld, z) / (np.polyval(ld, z) + np.polyval(ln, z)))
    ms = float(np.nanmax(sensitivity))
    return {
        "sensitivity_peak": ms,
        "sensitivity_peak_db": 20.0 * math.log10(ms),
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
