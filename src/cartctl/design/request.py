"""What a design is asked for, the same from the command line, ``tune`` and Python: every option
of ``cartctl design`` with its default and range, and the two forms it is recorded in (a
controller file's ``[request]`` table, the command line that regenerates the file). No numpy."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from dataclasses import dataclass, fields
from typing import Any

from cartctl.cart import PERIOD_S, SUPPLY_V, check_voltage_limit, nk_fits_loop_delay
from cartctl.choices import as_float, is_number, is_whole
from cartctl.errors import InputError
from cartctl.runtime.base import ANTI_WINDUP

METHODS = ("pi", "poles")
DEFAULT_PROCESS_NOISE_STD_V = 0.1  # V std per tick, the estimator's (cartctl.design.kalman)
DEFAULT_BIAS_DRIFT_STD_V = 0.03  # V std per tick, its input-disturbance random walk
PM_RANGE_DEG = (0.0, 89.0)  # (0, 89] degrees: at 90° the PI's proportional gain is gone
MAX_EXTRA_DELAY_TICKS = 50  # 0.5 s is no speed loop; the design's state grows by one per tick
MAX_LOOP_DELAY_TICKS = 100  # a recorded loop of at most 50 (identify --loop-delay) + 50 extra
MAX_TIMING_NOISE_TICKS = 10.0  # a command landing ±10 ticks late is no loop
MAX_NOISE_STD = 1e3  # V or rad/s: a variance of 1e6, the most a controller file's estimator holds
PI_ESTIMATORS = ("none", "kalman")
NOISE_FIELDS = (  # the estimator's, as design_kalman takes them
    "process_noise_std_v",
    "bias_drift_std_v",
    "extra_noise_std_rad_s",
    "timing_noise_std_ticks",
)


OPTIONS: dict[str, str] = {
    "phase_margin_deg": "--phase-margin",
    "crossover_hz": "--crossover-hz",
    "bandwidth_hz": "--bandwidth-hz",
    "anti_windup": "--anti-windup",
    "estimator": "--estimator",
    "poles": "--poles",
    "settling_time_s": "--settling-time",
    "overshoot_percent": "--overshoot",
    "process_noise_std_v": "--process-noise-v",
    "bias_drift_std_v": "--bias-drift-v",
    "extra_noise_std_rad_s": "--measurement-noise",
    "timing_noise_std_ticks": "--timing-noise-ticks",
    "extra_delay_ticks": "--extra-delay",
    "loop_delay_ticks": "--loop-delay",
    "voltage_limit_v": "--voltage-limit",
    "step_rad_s": "--step",
}
"""The ``cartctl design`` option of each request field."""


@dataclass(frozen=True)
class DesignRequest:
    """Everything a design is asked for: the options of ``cartctl design`` (:data:`OPTIONS`; their
    help gives the meaning), with their defaults and units. ``poles`` is the text given
    (``0.8,0.7+0.1j,0.7-0.1j``); ``loop_delay_ticks`` None is nk − 1 + extra delay
    (:func:`check_loop_delay`).
    """

    method: str
    phase_margin_deg: float = 65.0
    crossover_hz: float = 3.0
    bandwidth_hz: float | None = None
    anti_windup: str = "conditional"
    estimator: str = "none"
    poles: str | None = None
    settling_time_s: float = 0.06
    overshoot_percent: float = 1.0
    process_noise_std_v: float = DEFAULT_PROCESS_NOISE_STD_V
    bias_drift_std_v: float = DEFAULT_BIAS_DRIFT_STD_V
    extra_noise_std_rad_s: float = 0.0
    timing_noise_std_ticks: float = 0.0
    extra_delay_ticks: int = 0
    loop_delay_ticks: int | None = None
    voltage_limit_v: float = SUPPLY_V
    step_rad_s: float = 10.0

    def check(self, given: Collection[str] | None = None) -> DesignRequest:
        """This request, if each field its method uses is in range (:func:`check_field`, before
        any design work) and they combine; else InputError. A field it does not use is refused
        when in ``given`` (the options on a command line), else when it is not its default."""
        if self.method not in METHODS:
            raise InputError(f"method must be one of {', '.join(METHODS)}, got '{self.method}'")
        if self.estimator not in PI_ESTIMATORS:  # (the command line's choices)
            allowed = ", ".join(PI_ESTIMATORS)
            raise InputError(f"unknown estimator {self.estimator!r}; expected one of {allowed}")
        if self.anti_windup not in ANTI_WINDUP:  # (the runtime's line, before any design)
            allowed = ", ".join(ANTI_WINDUP)
            raise InputError(f"unknown anti-windup {self.anti_windup!r}; expected one of {allowed}")
        if self.poles is not None and not (isinstance(self.poles, str) and self.poles.strip()):
            raise InputError(
                f"--poles must be text like '0.8,0.7+0.1j,0.7-0.1j', got {self.poles!r}"
            )
        unused = _POLES_FIELDS if self.method == "pi" else _PI_FIELDS
        if self.method == "poles" and self.poles:
            unused = unused | _POLES_FIELDS  # the poles are given: no settling time or overshoot
        for f in fields(self):
            if f.name in RANGES and f.name not in unused:
                check_field(f.name, getattr(self, f.name))
        default = DesignRequest(method=self.method)
        idle = [
            (f, why)
            for f, why in self._idle().items()
            if (f in given if given is not None else getattr(self, f) != getattr(default, f))
        ]
        if idle:  # an option given that this request does not use: refused, not ignored
            names = [OPTIONS[f] for f, why in idle if why == idle[0][1]]
            are = "is" if len(names) == 1 else "are"
            raise InputError(f"{' and '.join(names)} {are} for {idle[0][1]}")
        return self

    def _idle(self) -> dict[str, str]:
        """The fields this request leaves unused, each with what would use it."""
        spec = ("settling_time_s", "overshoot_percent")
        if self.method == "poles":  # --estimator too: pole placement always has its Kalman one
            pi_only = ("phase_margin_deg", "crossover_hz", "bandwidth_hz", "anti_windup")
            idle = dict.fromkeys((*pi_only, "estimator"), "--method pi")
            why = "placing poles from a specification, not with --poles"
            return idle | dict.fromkeys(spec if self.poles else (), why)
        idle = dict.fromkeys(("poles", *spec), "--method poles")
        if self.bandwidth_hz is not None:
            idle["crossover_hz"] = "a PI without --bandwidth-hz"
        if self.estimator != "kalman":
            why = "an estimator; the PI runs without one unless --estimator kalman"
            idle |= dict.fromkeys(NOISE_FIELDS, why)
        return idle

    def file_request(self) -> dict[str, Any]:
        """The ``[request]`` table of a controller file: the options this method used."""
        names = ["extra_delay_ticks", "step_rad_s", *NOISE_FIELDS[:3]]
        if self.timing_noise_std_ticks:  # only when used: older files stay as they were
            names.append("timing_noise_std_ticks")
        if self.loop_delay_ticks is not None:
            names.append("loop_delay_ticks")
        if self.method == "pi":
            names += ["phase_margin_deg", "anti_windup", "estimator"]
            names.append("crossover_hz" if self.bandwidth_hz is None else "bandwidth_hz")
        else:
            names += ["poles"] if self.poles else ["settling_time_s", "overshoot_percent"]
        return {name: getattr(self, name) for name in names}

    def to_argv(self, model: str, *, always: tuple[str, ...] = ()) -> list[str]:
        """``cartctl design`` arguments (without the command name) that make this request;
        options at their default are left out, except the fields named in ``always``."""
        argv = [model, "--method", self.method]
        default = DesignRequest(method=self.method)
        for f in fields(self):
            if f.name == "method":
                continue
            value = getattr(self, f.name)
            if value is None or (value == getattr(default, f.name) and f.name not in always):
                continue
            argv += [OPTIONS[f.name], _text(value)]
        return argv


def _number(value: Any) -> bool:
    return is_number(value) and math.isfinite(as_float(value))


def _voltage_limit(value: Any) -> bool:
    if not _number(value):  # first: a huge whole number overflows the limit's float
        return False
    try:
        check_voltage_limit(value)
    except InputError:
        return False
    return True


def _whole(value: Any, high: int) -> bool:
    return is_whole(value) and 0 <= int(value) <= high


_NYQUIST_HZ = 0.5 / PERIOD_S
_BELOW_NYQUIST = f"in (0, {_NYQUIST_HZ:g}) Hz (below the Nyquist frequency of the {PERIOD_S * 1e3:g} ms tick)"  # fmt: skip

RANGES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "phase_margin_deg": (lambda v: _number(v) and PM_RANGE_DEG[0] < v <= PM_RANGE_DEG[1],
                         f"in (0, {PM_RANGE_DEG[1]:g}] degrees"),
    "crossover_hz": (lambda v: _number(v) and 0.0 < v < _NYQUIST_HZ, _BELOW_NYQUIST),
    "bandwidth_hz": (lambda v: v is None or (_number(v) and 0.0 < v < _NYQUIST_HZ),
                     _BELOW_NYQUIST),
    "settling_time_s": (lambda v: _number(v) and v > 0.0, "a positive number of seconds"),
    "overshoot_percent": (lambda v: _number(v) and 0.0 < v < 100.0, "in (0, 100) %"),
    "process_noise_std_v": (lambda v: _number(v) and 0.0 < v <= MAX_NOISE_STD,
                            f"a positive number of volts up to {MAX_NOISE_STD:g}"),
    "bias_drift_std_v": (lambda v: _number(v) and 0.0 <= v <= MAX_NOISE_STD,
                         f"a number of volts >= 0 and up to {MAX_NOISE_STD:g}"),
    "extra_noise_std_rad_s": (lambda v: _number(v) and 0.0 <= v <= MAX_NOISE_STD,
                              f"a number of rad/s >= 0 and up to {MAX_NOISE_STD:g}"),
    "timing_noise_std_ticks": (lambda v: _number(v) and 0.0 <= v <= MAX_TIMING_NOISE_TICKS,
                               f"in [0, {MAX_TIMING_NOISE_TICKS:g}] ticks"),
    "extra_delay_ticks": (lambda v: _whole(v, MAX_EXTRA_DELAY_TICKS),
                          f">= 0 ticks and at most {MAX_EXTRA_DELAY_TICKS} (0.5 s: beyond it "
                          "there is no speed loop)"),
    "loop_delay_ticks": (lambda v: v is None or _whole(v, MAX_LOOP_DELAY_TICKS),
                         f">= 0 ticks and at most {MAX_LOOP_DELAY_TICKS} (a recorded loop of at "
                         f"most 50 ticks and at most {MAX_EXTRA_DELAY_TICKS} extra)"),
    "voltage_limit_v": (_voltage_limit, f"in (0, {SUPPLY_V:g}] V"),
    "step_rad_s": (lambda v: _number(v) and v != 0.0, "a non-zero speed in rad/s"),
}  # fmt: skip
"""Per numeric request field: the test its value must pass (no model needed) and the range."""

_PI_FIELDS = frozenset({"phase_margin_deg", "crossover_hz", "bandwidth_hz"})
_POLES_FIELDS = frozenset({"settling_time_s", "overshoot_percent"})


def check_field(field: str, value: Any, option: str | None = None) -> Any:
    """``value`` if it is in the range of request field ``field`` (:data:`RANGES`), else the
    InputError ``OPTION must be RANGE, got VALUE``, ``option`` by default the design option."""
    test, allowed = RANGES[field]
    if not test(value):
        shown = f"{value:g}" if isinstance(value, float) else str(value)
        if isinstance(value, float) and not math.isfinite(value):  # not a number is no range
            allowed = "a number" if math.isnan(value) else "finite"
        raise InputError(f"{option or OPTIONS[field]} must be {allowed}, got {shown}")
    return value


def check_loop_delay(loop_delay_ticks: int | None, nk: int, extra_delay_ticks: int) -> int:
    """The loop delay of a design on a model with input delay ``nk`` and ``extra_delay_ticks``:
    None gives nk − 1 + extra; a given one may also be nk + extra (the next measurement, the
    tick's average speed, already sees part of a command that lands within the tick)."""
    derived = int(nk) - 1 + int(extra_delay_ticks)
    if loop_delay_ticks is None:
        return derived
    if not nk_fits_loop_delay(int(nk) + int(extra_delay_ticks), loop_delay_ticks):
        raise InputError(
            f"--loop-delay {loop_delay_ticks} does not fit a model with input delay nk = {nk} and "
            f"{extra_delay_ticks} extra tick(s): the loop delay is nk - 1 + extra ({derived}) or, "
            f"for a command that lands within the tick, nk + extra ({derived + 1})"
        )
    return int(loop_delay_ticks)


def _text(value: Any) -> str:  # 10.0 → '10', as typed
    return repr(value).removesuffix(".0") if isinstance(value, float) else str(value)


def parse_poles(text: str) -> list[complex]:
    """'0.8,0.7+0.1j,0.7-0.1j' → complex numbers; a clear error otherwise."""
    out = []
    for item in text.split(","):
        try:
            out.append(complex(item.strip().replace(" ", "")))
        except ValueError:
            raise InputError(
                f"--poles: '{item.strip()}' is not a number; write poles like 0.8 or 0.7+0.1j"
            ) from None
    return out
