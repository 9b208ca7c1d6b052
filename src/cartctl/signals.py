"""Excitation signals for ``cartctl excite``: amplitude in V, durations in s, one value per tick."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from cartctl.cart import PERIOD_S
from cartctl.choices import MAX_DURATION_S, SIGNALS, is_whole
from cartctl.errors import InputError


def _ticks(duration_s: float, period_s: float, what: str) -> int:
    if not (math.isfinite(duration_s) and duration_s > 0.0):
        raise InputError(f"{what} must be a positive number of seconds, got {duration_s}")
    if not (math.isfinite(period_s) and period_s > 0.0):
        raise InputError(f"sample period must be a positive number of seconds, got {period_s}")
    n = round(duration_s / period_s)
    if n < 1:
        raise InputError(
            f"{what} of {duration_s} s is shorter than one sample period ({period_s} s)"
        )
    return n


def _start(amplitude: float, duration_s: float, period_s: float, what: str) -> tuple[float, int]:
    """The checked amplitude and the length in ticks."""
    if not (math.isfinite(amplitude) and amplitude > 0.0):
        raise InputError(f"amplitude must be a positive finite number, got {amplitude}")
    return float(amplitude), _ticks(duration_s, period_s, what)


def square(
    amplitude_v: float, *, hold_s: float = 1.0, cycles: int = 5, period_s: float = PERIOD_S
) -> NDArray[np.float64]:
    """The report's excitation: +A, 0, −A for ``hold_s`` each, ``cycles`` times (no DC)."""
    amp, n = _start(amplitude_v, hold_s, period_s, "hold time")
    if not is_whole(cycles) or cycles < 1:
        raise InputError(f"cycles must be a whole number >= 1, got {cycles!r}")
    one = np.concatenate([np.full(n, amp), np.zeros(n), np.full(n, -amp)])
    return np.tile(one, cycles)


def step(
    amplitude_v: float, *, duration_s: float = 3.0, delay_s: float = 0.5, period_s: float = PERIOD_S
) -> NDArray[np.float64]:
    """Zero for ``delay_s``, then ``amplitude_v`` until ``duration_s`` (total length)."""
    amp, n = _start(amplitude_v, duration_s, period_s, "duration")
    if not (math.isfinite(delay_s) and 0.0 <= delay_s < duration_s):
        raise InputError(f"step delay must be in [0, duration), got {delay_s} s")
    out = np.zeros(n)
    out[round(delay_s / period_s) :] = amp
    return out


def prbs(
    amplitude_v: float,
    *,
    duration_s: float = 15.0,
    bit_s: float = 0.05,
    order: int = 8,
    seed: int = 1,
    period_s: float = PERIOD_S,
) -> NDArray[np.float64]:
    """±A from a maximum-length shift register of ``order`` bits (period 2**order − 1 bits).

    A bit lasts ``bit_s`` (s), so the band reaches about 0.44 / bit_s Hz; ``seed`` is the
    non-zero initial register state.
    """
    amp, n = _start(amplitude_v, duration_s, period_s, "duration")
    per_bit = _ticks(bit_s, period_s, "bit duration")
    if not (is_whole(order) and 2 <= order <= 32):
        raise InputError(f"PRBS order must be a whole number in 2..32, got {order!r}")
    if not is_whole(seed):
        raise InputError(f"PRBS seed must be a whole number, got {seed!r}")
    state = np.array([(seed >> i) & 1 for i in range(order)], dtype=np.int8)
    if not state.any():
        raise InputError("PRBS seed must have a non-zero low-order bit pattern")
    from scipy import signal as sps

    bits, _ = sps.max_len_seq(int(order), state=state)
    levels = np.where(np.resize(bits, -(-n // per_bit)) > 0, amp, -amp)  # the sequence repeated
    return np.repeat(levels, per_bit)[:n]


def multisine(
    amplitude_v: float,
    *,
    duration_s: float = 15.36,
    cycle_s: float = 2.56,
    f_min_hz: float = 0.5,
    f_max_hz: float = 20.0,
    period_s: float = PERIOD_S,
) -> NDArray[np.float64]:
    """Equal-amplitude harmonics of 1/cycle_s in [f_min_hz, f_max_hz] with Schroeder phases
    (crest factor about 1.5–1.8, not √(2N)), scaled to a peak of ``amplitude_v``."""
    amp, n = _start(amplitude_v, duration_s, period_s, "duration")
    n_cycle = _ticks(cycle_s, period_s, "cycle time")
    nyquist_hz = 0.5 / period_s
    if not (0.0 < f_min_hz <= f_max_hz < nyquist_hz):
        raise InputError(
            f"multisine band must satisfy 0 < f_min <= f_max < {nyquist_hz:g} Hz, "
            f"got {f_min_hz}..{f_max_hz} Hz"
        )
    df = 1.0 / (n_cycle * period_s)
    harmonics = np.arange(max(1, math.ceil(f_min_hz / df)), math.floor(f_max_hz / df) + 1)
    if harmonics.size == 0:
        raise InputError(
            f"no harmonic of {df:g} Hz lies in {f_min_hz}..{f_max_hz} Hz; lengthen the cycle"
        )
    k = np.arange(1, harmonics.size + 1)
    phases = -np.pi * k * (k - 1) / harmonics.size
    t = np.arange(n_cycle) * period_s
    one = np.cos(2.0 * np.pi * df * np.outer(t, harmonics) + phases).sum(axis=1)
    one *= amp / np.max(np.abs(one))
    return np.resize(one, n)


def chirp(
    amplitude_v: float,
    *,
    duration_s: float = 20.0,
    f_start_hz: float = 0.1,
    f_end_hz: float = 20.0,
    period_s: float = PERIOD_S,
) -> NDArray[np.float64]:
    """A logarithmic sine sweep from ``f_start_hz`` to ``f_end_hz`` over ``duration_s``."""
    amp, n = _start(amplitude_v, duration_s, period_s, "duration")
    nyquist_hz = 0.5 / period_s
    if not (0.0 < f_start_hz < nyquist_hz and 0.0 < f_end_hz < nyquist_hz):
        raise InputError(
            f"chirp frequencies must lie in (0, {nyquist_hz:g}) Hz, got {f_start_hz}..{f_end_hz}"
        )
    t = np.arange(n) * period_s
    from scipy import signal as sps

    return amp * sps.chirp(
        t, f0=f_start_hz, t1=t[-1] if n > 1 else period_s, f1=f_end_hz, method="logarithmic"
    )


def ramp(
    slope_per_s: float,
    *,
    duration_s: float = 5.0,
    limit: float | None = None,
    period_s: float = PERIOD_S,
) -> NDArray[np.float64]:
    """A ramp from 0 rising ``slope_per_s`` units per second, held at ``limit`` when given."""
    if not math.isfinite(slope_per_s):
        raise InputError(f"ramp slope must be finite, got {slope_per_s}")
    n = _ticks(duration_s, period_s, "duration")
    out = slope_per_s * np.arange(n, dtype=np.float64) * period_s
    return out if limit is None else np.clip(out, -abs(limit), abs(limit))


_BY_DURATION: dict[str, Callable[..., NDArray[np.float64]]] = {
    "step": step, "prbs": prbs, "multisine": multisine, "chirp": chirp
}  # fmt: skip


def make_signal(
    name: str,
    amplitude_v: float,
    *,
    cycles: int | None = None,
    duration_s: float | None = None,
    period_s: float = PERIOD_S,
) -> NDArray[np.float64]:
    """An excitation by name (:data:`~cartctl.choices.SIGNALS`) with ``cartctl excite``'s defaults.

    ``cycles`` counts the +A/0/−A cycles of 'square' (default 5) or the 2.56 s periods of
    'multisine' (default 6); ``duration_s`` is the length of the others (s).
    """
    if name not in SIGNALS:
        raise InputError(f"unknown signal '{name}'; choose one of {', '.join(SIGNALS)}")
    if cycles is not None and not is_whole(cycles):
        raise InputError(f"--cycles must be a whole number, got {cycles!r}")
    if cycles is not None and cycles < 1:
        raise InputError(f"--cycles must be at least 1, got {cycles}")
    if cycles is not None and name not in ("square", "multisine"):
        raise InputError(f"--cycles does not apply to the {name} signal; use --duration")
    if cycles is not None and duration_s is not None:
        raise InputError(f"--cycles and --duration both set the {name} signal's length; give one")
    if cycles is not None:
        cycle_s = 3.0 if name == "square" else 2.56
        if cycles * cycle_s > MAX_DURATION_S:
            raise InputError(
                f"--cycles {cycles} of {name} are {cycles * cycle_s:g} s of signal; at most "
                f"{int(MAX_DURATION_S // cycle_s)} ({MAX_DURATION_S / 3600:g} h)"
            )
    if name == "square":
        return square(amplitude_v, cycles=int(cycles or 5), period_s=period_s)
    shortest = 0.5 + period_s  # a tick of step after step()'s delay_s
    if name == "step" and duration_s and duration_s < shortest:
        raise InputError(
            f"--duration {duration_s:g} s ends before the step (0 V for its first "
            f"0.5 s); give at least {shortest:g} s"
        )
    if name == "multisine" and cycles:
        duration_s = 2.56 * cycles
    given = {"duration_s": duration_s} if duration_s else {}  # else each one's default
    return _BY_DURATION[name](amplitude_v, **given, period_s=period_s)
