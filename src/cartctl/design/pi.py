"""Discrete PI speed controller design on an identified ARX model (pure maths, no I/O).

The PI (backward-Euler integral; :class:`cartctl.runtime.pi.PiController` runs it)::

    I[k] = I[k−1] + Ki·Ts·e[k],     u[k] = Kp·e[k] + I[k]
    C(z) = Kp + Ki·Ts·z/(z − 1) = ((Kp + Ki·Ts)·z − Kp) / (z − 1)

e = reference − speed (rad/s), u in V, Kp in V/(rad/s), Ki in V/rad, Ts in s. The design puts
the open loop L = C·G·z^−extra on the unit circle at the crossover with ∠L = −180° + PM: one
complex equation, linear in (Kp, Ki). Where the solution needs Kp < 0 (a low crossover on a plant
with little lag) or Ki ≤ 0 (a high one: phase lead) it is refused with the crossovers that work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.design.request import PM_RANGE_DEG
from cartctl.errors import InputError
from cartctl.model import ArxModel, check_extra_delay_ticks


def _check_common(model: ArxModel, phase_margin_deg: float, extra_delay_ticks: int) -> None:
    if not model.is_stable():
        raise InputError(
            f"the model is {model.stability()} (a pole on or outside the unit circle); this PI "
            "design needs a stable model"
        )
    if not (math.isfinite(phase_margin_deg) and 0.0 < phase_margin_deg <= PM_RANGE_DEG[1]):
        raise InputError(
            f"phase margin must be in (0, {PM_RANGE_DEG[1]:g}] degrees, got {phase_margin_deg}"
        )
    check_extra_delay_ticks(extra_delay_ticks)


def pi_tf_coeffs(
    kp: float, ki: float, period_s: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """C(z) = Kp + Ki·Ts·z/(z − 1) from error to voltage: ``([Kp + Ki·Ts, −Kp], [1, −1])``."""
    return np.array([kp + ki * period_s, -kp]), np.array([1.0, -1.0])


def _loop_coeffs(
    model: ArxModel, kp: float, ki: float, extra: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Open loop C·G·z^−extra as (num, den), descending powers of z."""
    c_num, c_den = pi_tf_coeffs(kp, ki, model.period_s)
    num = np.polymul(c_num, model.num())
    den = np.polymul(np.polymul(c_den, model.den()), np.r_[1.0, np.zeros(extra)])
    return np.asarray(num, dtype=np.float64), np.asarray(den, dtype=np.float64)


def _gains(
    model: ArxModel, phase_margin_deg: float, freq_hz: NDArray[np.float64], extra: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Kp, Ki (arrays) that put L(e^{jωTs}) at angle −180° + PM on the unit circle."""
    ts = model.period_s
    z = np.exp(2j * np.pi * freq_hz * ts)
    plant = model.response_at(z) * z ** (-extra)
    target = np.exp(1j * np.deg2rad(phase_margin_deg - 180.0)) / plant  # required C(e^{jωTs})
    w = ts * z / (z - 1.0)  # C = Kp·1 + Ki·w: Re and Im give two real equations
    ki = target.imag / w.imag
    kp = target.real - ki * w.real
    return kp, ki


def _solve(model: ArxModel, pm: float, freq_hz: float, extra: int) -> tuple[float, float, str]:
    """(Kp, Ki, why a PI cannot meet (pm, freq_hz), or '')."""
    kp, ki = (float(v[0]) for v in _gains(model, pm, np.array([freq_hz]), extra))
    return kp, ki, _problem(model, pm, kp, ki, extra)


def _problem(model: ArxModel, pm: float, kp: float, ki: float, extra: int) -> str:
    if kp < 0.0:
        return (
            f"it would need Kp = {kp:.3g} V/(rad/s) < 0: there even a pure integrator leaves more "
            f"than {pm:g}° of margin"
        )
    if ki <= 0.0:
        return (
            f"it would need Ki = {ki:.3g} V/rad <= 0: there even a pure gain leaves less than "
            f"{pm:g}° of margin"
        )
    num, den = _loop_coeffs(model, kp, ki, extra)
    if not np.all(np.abs(np.roots(np.polyadd(den, num))) < 1.0):
        return "the closed loop would be unstable"
    return ""


def crossover_range(
    model: ArxModel, *, phase_margin_deg: float, extra_delay_ticks: int = 0
) -> tuple[float, float] | None:
    """(low_hz, high_hz): the lowest band of crossovers at which a PI gives exactly this phase
    margin with Kp ≥ 0, Ki > 0 and a stable loop, edges bisected to about 1e-6 Hz; None when no
    crossover below Nyquist works."""
    _check_common(model, phase_margin_deg, extra_delay_ticks)
    nyquist = 0.5 / model.period_s
    grid = np.geomspace(nyquist * 1e-4, nyquist * (1.0 - 1e-6), 400)
    kp, ki = _gains(model, phase_margin_deg, grid, extra_delay_ticks)  # the whole grid at once
    ok = [not _problem(model, phase_margin_deg, float(p), float(i), extra_delay_ticks)
          for p, i in zip(kp, ki, strict=True)]  # fmt: skip
    if not any(ok):
        return None
    first = ok.index(True)
    last = ok.index(False, first) - 1 if False in ok[first:] else len(ok) - 1

    def edge(good: float, bad: float) -> float:
        while abs(good - bad) > 1e-7:  # a tenth of the 1e-6 Hz promised
            mid = 0.5 * (good + bad)
            if not _solve(model, phase_margin_deg, mid, extra_delay_ticks)[2]:
                good = mid
            else:
                bad = mid
        return good

    low = edge(grid[first], grid[first - 1]) if first > 0 else float(grid[0])
    high = edge(grid[last], grid[last + 1]) if last < len(grid) - 1 else float(grid[-1])
    return float(low), float(high)


def _range_text(model: ArxModel, pm: float, extra: int) -> str:
    span = crossover_range(model, phase_margin_deg=pm, extra_delay_ticks=extra)
    if span is None:
        return f"no crossover below Nyquist gives {pm:g}° on this model; try a smaller margin"
    low, high = math.ceil(span[0] * 100.0) / 100.0, math.floor(span[1] * 100.0) / 100.0
    return f"for {pm:g}° the crossover must lie between {low:.2f} Hz and {high:.2f} Hz"


def design_pi(
    model: ArxModel,
    *,
    phase_margin_deg: float,
    crossover_hz: float,
    extra_delay_ticks: int = 0,
) -> PiDesign:
    """PI gains for an exact phase margin (degrees, in (0, 89]) at a gain crossover (Hz, below
    Nyquist) on a stable model, with ``extra_delay_ticks`` of loop delay beyond the model's;
    InputError for a request no PI meets (with the crossovers that work for that margin)."""
    _check_common(model, phase_margin_deg, extra_delay_ticks)
    nyquist = 0.5 / model.period_s
    if not (math.isfinite(crossover_hz) and 0.0 < crossover_hz < nyquist):
        raise InputError(
            f"crossover must be in (0, {nyquist:g}) Hz (below Nyquist), got {crossover_hz}"
        )
    extra = int(extra_delay_ticks)
    kp, ki, problem = _solve(model, phase_margin_deg, crossover_hz, extra)
    if problem:
        raise InputError(
            f"a PI cannot give {phase_margin_deg:g}° phase margin at {crossover_hz:g} Hz on this "
            f"model ({problem}); {_range_text(model, phase_margin_deg, extra)}"
        )
    return PiDesign(kp, ki, model.period_s, extra, model, phase_margin_deg, crossover_hz)


def design_pi_bandwidth(
    model: ArxModel,
    *,
    bandwidth_hz: float,
    phase_margin_deg: float = 60.0,
    extra_delay_ticks: int = 0,
) -> PiDesign:
    """PI gains for a closed-loop (reference → speed) −3 dB bandwidth (Hz) at a phase margin:
    the crossover by ``brentq`` inside :func:`crossover_range`, on the branch where the bandwidth
    grows with it (of two crossovers with the same bandwidth, the lower). InputError as
    :func:`design_pi`, or for a bandwidth no crossover gives (with those it can).
    """
    pm, extra = phase_margin_deg, extra_delay_ticks
    span = crossover_range(model, phase_margin_deg=pm, extra_delay_ticks=extra)
    if not (math.isfinite(bandwidth_hz) and bandwidth_hz > 0.0):
        raise InputError(f"bandwidth must be a positive number of Hz, got {bandwidth_hz}")
    if span is None:
        raise InputError(_range_text(model, pm, extra))
    low, high = span[0] + 1e-6 * (span[1] - span[0]), span[1] - 1e-6 * (span[1] - span[0])

    def at(fc: float) -> PiDesign:
        return design_pi(model, phase_margin_deg=pm, crossover_hz=fc, extra_delay_ticks=extra)

    grid = np.linspace(low, high, 41)
    widths = [at(fc).bandwidth_hz() for fc in grid]
    top = int(np.argmax(widths))
    if not widths[0] <= bandwidth_hz <= widths[top]:
        low_text, high_text = math.ceil(widths[0] * 100.0), math.floor(widths[top] * 100.0)
        raise InputError(  # the ends rounded inwards, as _range_text's: both can be asked for
            f"a PI with {pm:g}° phase margin cannot give a {bandwidth_hz:g} Hz closed-loop "
            f"bandwidth on this model; it gives {low_text / 100:.2f} Hz to {high_text / 100:.2f} Hz"
        )
    fc = float(grid[top])
    if bandwidth_hz < widths[top]:
        from scipy import optimize

        fc = optimize.brentq(lambda f: at(f).bandwidth_hz() - bandwidth_hz, low, fc, xtol=1e-9)
    return replace(at(fc), target_bandwidth_hz=float(bandwidth_hz))


@dataclass(frozen=True)
class PiDesign:
    """A PI design: Kp (V/(rad/s)), Ki (V/rad), Ts (s), the extra loop delay (ticks), the model
    and the request (for a bandwidth design, the crossover found for it, and the bandwidth)."""

    kp: float
    ki: float
    period_s: float
    extra_delay_ticks: int
    model: ArxModel
    target_phase_margin_deg: float
    target_crossover_hz: float
    target_bandwidth_hz: float | None = None

    def controller_tf_coeffs(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """C(z) from error (rad/s) to voltage (V): ``([Kp + Ki·Ts, −Kp], [1, −1])``, powers of z."""
        return pi_tf_coeffs(self.kp, self.ki, self.period_s)

    def _loop(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _loop_coeffs(self.model, self.kp, self.ki, self.extra_delay_ticks)

    def open_loop(self) -> Any:
        """L(z) = C(z)·G(z)·z^−extra as a python-control ``TransferFunction`` (dt = Ts)."""
        import control

        return control.tf(*self._loop(), dt=self.period_s)

    def closed_loop(self) -> Any:
        """Reference → speed, L / (1 + L), as a python-control ``TransferFunction`` (dt = Ts)."""
        import control

        return control.feedback(self.open_loop())

    def bandwidth_hz(self) -> float:
        """Closed-loop −3 dB bandwidth (Hz): where |T| = |L/(1 + L)| first falls below 1/√2;
        Nyquist if never."""
        num, den = self._loop()
        nyquist = 0.5 / self.period_s
        grid = np.linspace(0.0, nyquist, 4001)

        def excess(f: float | NDArray[np.float64]) -> Any:
            z = np.exp(2j * np.pi * np.atleast_1d(f) * self.period_s)
            n, d = np.polyval(num, z), np.polyval(den, z)
            return np.abs(n / (d + n)) - 1.0 / math.sqrt(2.0)

        below = np.flatnonzero(excess(grid) < 0.0)
        if below.size == 0:
            return nyquist
        i = int(below[0])
        from scipy import optimize

        return float(optimize.brentq(lambda f: float(excess(f)[0]), grid[i - 1], grid[i]))

    def analysis(self) -> dict[str, Any]:
        """Margins (:func:`~cartctl.design.analysis.loop_analysis`), ``closed_loop_poles``
        ([[re, im], ...]), sensitivity peak and ``bandwidth_hz``."""
        from cartctl.design.analysis import loop_analysis

        loop = loop_analysis(*self.controller_tf_coeffs(), self.model, self.extra_delay_ticks)
        num, den = self._loop()
        poles = sorted(np.roots(np.polyadd(den, num)), key=lambda p: (abs(p), p.imag))
        margins = {k: loop[k] for k in ("phase_margin_deg", "gain_margin_db", "crossover_hz")}
        return {
            **margins,
            "closed_loop_poles": [[float(p.real), float(p.imag)] for p in poles],
            "sensitivity_peak": loop["sensitivity_peak"],
            "sensitivity_peak_db": loop["sensitivity_peak_db"],
            "bandwidth_hz": self.bandwidth_hz(),
        }

    def to_dict(self) -> dict[str, Any]:
        """``design --json`` entry of one motor (without the simulated ``step``)."""
        num, den = self.controller_tf_coeffs()
        own = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "model"}
        tf = {"controller_num": num.tolist(), "controller_den": den.tolist()}
        return {**own, **tf, **self.analysis()}
