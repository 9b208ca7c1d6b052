"""What a design is asked for: one request, the same from the command line, ``tune`` and Python.

:class:`DesignRequest` holds every option of ``cartctl design`` with its default, checks them, and
knows both forms it is recorded in: the ``[request]`` table of a controller file and the command
line that regenerates the file (:meth:`DesignRequest.to_argv`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from cartctl.cart import SUPPLY_V
from cartctl.errors import InputError

METHODS = ("pi", "poles")
DEFAULT_PROCESS_NOISE_STD_V = 0.1
"""The estimator's input-equivalent white voltage disturbance (V std per tick); see
:mod:`cartctl.design.kalman`."""
DEFAULT_BIAS_DRIFT_STD_V = 0.03
"""Random-walk step of the estimator's input-disturbance state (V std per tick); see
:mod:`cartctl.design.kalman`."""
ANTI_WINDUP = ("conditional", "back-calculation", "none")
PI_ESTIMATORS = ("none", "kalman")
ESTIMATOR_GAINS = ("time-varying", "steady-state")
"""The estimator's gain: filterpy's KalmanFilter (time-varying) or the fixed DARE gain."""
_OLD_GAIN_NAMES = {"kalman": "time-varying"}


def estimator_gain_name(name: str) -> str:
    """The current name of an estimator gain: ``'kalman'``, its old name, is ``'time-varying'``."""
    return _OLD_GAIN_NAMES.get(name, name)


OPTIONS: dict[str, str] = {
    "phase_margin_deg": "--phase-margin",
    "crossover_hz": "--crossover-hz",
    "bandwidth_hz": "--bandwidth-hz",
    "anti_windup": "--anti-windup",
    "estimator": "--estimator",
    "poles": "--poles",
    "settling_time_s": "--settling-time",
    "overshoot_percent": "--overshoot",
    "estimator_gain": "--estimator-gain",
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
    """Everything a design is asked for (the options of ``cartctl design``, with their defaults).

    Attributes
    ----------
    method : {'pi', 'poles'}
    phase_margin_deg, crossover_hz : float
        PI: phase margin (deg) at the crossover frequency (Hz).
    bandwidth_hz : float or None
        PI: design for this closed-loop bandwidth (Hz) instead of a crossover.
    anti_windup : {'conditional', 'back-calculation', 'none'}
        PI: integrator handling at the voltage limit.
    estimator : {'none', 'kalman'}
        PI: run on the measurement, or on a Kalman speed estimate.
    poles : str or None
        Pole placement: closed-loop poles as given (``0.8,0.7+0.1j,0.7-0.1j``).
    settling_time_s, overshoot_percent : float
        Pole placement: the dominant poles' 2 % settling time (s) and overshoot (%).
    estimator_gain : {'time-varying', 'steady-state'}
        filterpy's filter with its time-varying gain, or the fixed steady-state gain. ``'kalman'``,
        the old name of ``'time-varying'`` (both are Kalman gains), is read as it.
    process_noise_std_v, bias_drift_std_v : float
        The estimator's process noise (V) and its disturbance state's random walk (V per tick).
    extra_noise_std_rad_s : float
        Measurement noise beyond the encoder's quantisation (rad/s); the estimator's √R is this
        and the quantisation noise together.
    timing_noise_std_ticks : float
        σ_ε, how uncertain (std, ticks) the moment a command lands is: the time-varying
        estimator adds (σ_ε Δu)² B Bᵀ to its process noise after each command change Δu (see
        :class:`~cartctl.runtime.kalman.KalmanDesign`); 0 leaves Q fixed.
    extra_delay_ticks : int
        Ticks of loop delay beyond the model's (a PC-side loop over serial).
    loop_delay_ticks : int or None
        The loop delay the controller is for (ticks from a measurement to its voltage on the
        motor), when it is not the model's nk − 1 + extra delay: nk + extra delay is allowed too,
        for a model whose next measurement already sees part of a command (it lands within the
        tick; :func:`check_loop_delay`). None: nk − 1 + extra delay.
    voltage_limit_v : float
        Command saturation (V), at most the 12 V supply.
    step_rad_s : float
        Reference step of the simulated response (rad/s).
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
    estimator_gain: str = "time-varying"
    process_noise_std_v: float = DEFAULT_PROCESS_NOISE_STD_V
    bias_drift_std_v: float = DEFAULT_BIAS_DRIFT_STD_V
    extra_noise_std_rad_s: float = 0.0
    timing_noise_std_ticks: float = 0.0
    extra_delay_ticks: int = 0
    loop_delay_ticks: int | None = None
    voltage_limit_v: float = SUPPLY_V
    step_rad_s: float = 10.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "estimator_gain", estimator_gain_name(self.estimator_gain))

    def check(self) -> DesignRequest:
        """This request, if its options are in range (one-line :class:`InputError` otherwise)."""
        if self.estimator_gain not in ESTIMATOR_GAINS:
            raise InputError(
                f"estimator gain must be one of {', '.join(ESTIMATOR_GAINS)}, got "
                f"'{self.estimator_gain}'"
            )
        if self.method not in METHODS:
            raise InputError(f"method must be one of {', '.join(METHODS)}, got '{self.method}'")
        if not 0.0 < self.voltage_limit_v <= SUPPLY_V:
            raise InputError(
                f"--voltage-limit must be in (0, {SUPPLY_V:g}] V, got {self.voltage_limit_v}"
            )
        if self.extra_delay_ticks < 0:
            raise InputError(f"--extra-delay must be >= 0 ticks, got {self.extra_delay_ticks}")
        if self.loop_delay_ticks is not None and self.loop_delay_ticks < 0:
            raise InputError(f"--loop-delay must be >= 0 ticks, got {self.loop_delay_ticks}")
        timing = self.timing_noise_std_ticks
        if not (math.isfinite(timing) and 0.0 <= timing <= 10.0):
            raise InputError(f"--timing-noise-ticks must be in [0, 10] ticks, got {timing}")
        if timing > 0.0 and self.estimator_gain != "time-varying":
            raise InputError(
                "--timing-noise-ticks needs --estimator-gain time-varying (a fixed gain cannot "
                "follow the command's changes)"
            )
        if timing > 0.0 and self.method == "pi" and self.estimator != "kalman":
            raise InputError("--timing-noise-ticks is for an estimator; the PI runs without one "
                             "unless --estimator kalman")  # fmt: skip
        if not (math.isfinite(self.step_rad_s) and self.step_rad_s != 0.0):
            raise InputError(f"--step must be a non-zero speed in rad/s, got {self.step_rad_s}")
        return self

    def pole_list(self) -> list[complex] | None:
        """:attr:`poles` as complex numbers (None when not given)."""
        return None if not self.poles else parse_poles(self.poles)

    def file_request(self) -> dict[str, Any]:
        """The ``[request]`` table of a controller file: the options this method used."""
        req: dict[str, Any] = {
            "extra_delay_ticks": self.extra_delay_ticks, "step_rad_s": self.step_rad_s,
            "estimator_gain": self.estimator_gain, "process_noise_std_v": self.process_noise_std_v,
            "bias_drift_std_v": self.bias_drift_std_v,
            "extra_noise_std_rad_s": self.extra_noise_std_rad_s,
        }  # fmt: skip
        if self.timing_noise_std_ticks:  # only when used: older files stay as they were
            req["timing_noise_std_ticks"] = self.timing_noise_std_ticks
        if self.loop_delay_ticks is not None:
            req["loop_delay_ticks"] = self.loop_delay_ticks
        if self.method == "pi":
            req.update(phase_margin_deg=self.phase_margin_deg, anti_windup=self.anti_windup,
                       estimator=self.estimator)  # fmt: skip
            if self.bandwidth_hz is not None:
                req["bandwidth_hz"] = self.bandwidth_hz
            else:
                req["crossover_hz"] = self.crossover_hz
        elif self.poles:
            req["poles"] = self.poles
        else:
            req.update(
                settling_time_s=self.settling_time_s, overshoot_percent=self.overshoot_percent
            )
        return req

    def to_argv(self, model: str, *, always: tuple[str, ...] = ()) -> list[str]:
        """``cartctl design`` arguments (without the command name) that make this request.

        Options left at their default are left out, except the fields named in ``always``.
        """
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


def check_loop_delay(loop_delay_ticks: int | None, nk: int, extra_delay_ticks: int) -> int:
    """The loop delay of a design on a model with input delay ``nk`` and ``extra_delay_ticks``.

    None gives nk − 1 + extra (the report's timing: a command lands at the tick after the
    measurement it answers, and shows in the measurement after that). A given loop delay may
    also be nk + extra: the model's next measurement already sees part of a command that lands
    within the tick (the measured speed is the tick's average), as a model identified on a cart
    whose commands land a few ms after the tick has it. Anything else is refused (one line).
    """
    derived = int(nk) - 1 + int(extra_delay_ticks)
    if loop_delay_ticks is None:
        return derived
    if loop_delay_ticks not in (derived, derived + 1):
        raise InputError(
            f"--loop-delay {loop_delay_ticks} does not fit a model with input delay nk = {nk} and "
            f"{extra_delay_ticks} extra tick(s): the loop delay is nk - 1 + extra ({derived}) or, "
            f"for a command that lands within the tick, nk + extra ({derived + 1})"
        )
    return int(loop_delay_ticks)


def _text(value: Any) -> str:
    if isinstance(value, float):
        text = repr(value)
        return text[:-2] if text.endswith(".0") else text
    return str(value)


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
