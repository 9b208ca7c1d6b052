"""A designed controller as C for the cart's ``control()`` (the course template on microOS).

Where it sits: after ``design``; ``cartctl export CONTROLLER.toml --arduino`` prints what
:func:`arduino_source` returns. The C runs the same difference equations, anti-windup and estimator
as the runtime controllers (:class:`~cartctl.runtime.pi.PiController`,
:class:`~cartctl.runtime.statefeedback.StateFeedbackController`), line for line and in ``float``
(the Arduino Mega has no wider type), with these differences:

- the Kalman estimator always runs its steady-state (fixed) gain L, as
  :class:`~cartctl.runtime.kalman.SteadyStateSpeedEstimator` does; compare it with the runtime
  controller of :func:`as_steady_state`;
- a file whose estimator has timing noise (``timing_noise_std_ticks`` > 0, a gain that moves
  after each command change in cartctl's loop) runs without it: the C keeps the fixed L, which
  the moving gain returns to while the command holds; the header says so and
  ``cartctl export`` warns (:func:`timing_noise_note`);
- float32 arithmetic: the voltages agree with the runtime's to within 1e-4 of the voltage range
  (a few µV for the PI; up to 0.2 mV for state feedback, which sums terms of tens of volts), and
  values beyond 3.4e38 overflow sooner (a command that overflows gives 0 V on both).

The text is C99 that is also valid C++ (the template compiles ``robot.cpp`` as C++), uses only
``<math.h>`` (``isfinite``), and is deterministic: the same file gives the same text.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

from cartctl import __version__
from cartctl.cart import PERIOD_S
from cartctl.design.build import build_controllers
from cartctl.design.controllerfile import ControllerFile, load_controller
from cartctl.errors import InputError
from cartctl.export.c_code import c_float, pi_code, poles_code, where
from cartctl.link.firmware_id import (
    CH_FIRMWARE_ID,
    IN_REFERENCE,
    ONBOARD_ID,
    ONBOARD_LAYOUT,
    OUT_REFERENCE,
    OUT_SPEED,
    OUT_VOLTAGE,
)
from cartctl.runtime.base import Controller

__all__ = ["arduino_source", "as_steady_state", "c_float", "timing_noise_note"]


def timing_noise_note(controller: ControllerFile) -> str | None:
    """One line when the file's estimator has timing noise, which the C does not run; else None."""
    sigma = max(
        (float(e.get("estimator", {}).get("timing_noise_std_ticks", 0.0))
         for e in controller.motors.values()),
        default=0.0,
    )  # fmt: skip
    if sigma <= 0.0:
        return None
    return (
        f"the estimator's timing noise ({sigma:g} ticks) is not in the C, which runs the fixed "
        "steady-state gain L (cartctl's loop moves the gain after each command change)"
    )


def as_steady_state(controller: ControllerFile) -> ControllerFile:
    """The same controller file without timing noise: the fixed-gain estimator (what the C runs)."""
    motors = {
        m: {**e, "estimator": {**e["estimator"], "timing_noise_std_ticks": 0.0}}
        if "estimator" in e
        else e
        for m, e in controller.motors.items()
    }
    return dataclasses.replace(controller, motors=motors)


def onboard_controllers(path: str | Path) -> dict[str, Controller]:
    """The controllers of a controller file as the exported C runs them (fixed-gain estimator).

    Raises
    ------
    InputError
        The file was designed for another period than the cart's 10 ms.
    MissingFileError, DataFileError
        The file is missing or does not hold a controller.
    """
    controller = load_controller(path)
    if not math.isclose(controller.period_s, PERIOD_S, rel_tol=1e-9):
        raise InputError(
            f"{path} was designed for a period of {controller.period_s:g} s; the cart's "
            f"control() runs every {PERIOD_S:g} s"
        )
    return build_controllers(as_steady_state(controller))


def _usage(motors: Sequence[str]) -> list[str]:
    """The header's example of ``Robot::control()`` for the motors present."""
    lines = ["  void Robot::control() {"]
    channel = IN_REFERENCE
    for m in motors:
        lines.append(
            f"    float reference_{m}_rad_s = readFloat({channel[m]});  "
            f"// float channel {channel[m]} from the PC"
        )
    for m in motors:
        lines.append(f"    float speed_{m}_rad_s = getSpeedMotor{m.upper()}();")
    lines.append("    " + " ".join(f"float voltage_{m}_v = 0.0f;" for m in motors))
    lines.append("    if (controlEnabled()) {  // the template's button 0 in QRC")
    for m in motors:
        lines.append(
            f"      voltage_{m}_v = cartctl_step_{m}(reference_{m}_rad_s, speed_{m}_rad_s);"
        )
    lines.append("    } else {")
    for m in motors:
        lines.append(f"      cartctl_reset_{m}();  // start afresh when enabled again")
    lines.append("    }")
    for m in motors:
        lines.append(f"    setVoltageMotor{m.upper()}(voltage_{m}_v);")
    outputs = (("speed_{}_rad_s", OUT_SPEED), ("voltage_{}_v", OUT_VOLTAGE),
               ("reference_{}_rad_s", OUT_REFERENCE))  # fmt: skip
    for name, first in outputs:
        for m in motors:
            lines.append(f"    writeFloat({first + channel[m]}, {name.format(m)});")
    lines[-len(outputs) * len(motors)] += "  // out to the PC: cartctl monitor, QRC"
    lines.append(
        "    writeFloat(CARTCTL_FIRMWARE_ID_CHANNEL, CARTCTL_FIRMWARE_ID);  "
        "// the layout, for cartctl monitor"
    )
    lines.append("  }")
    return ["//" + (" " + line if line else "") for line in lines]


def _header(controller: ControllerFile, command: str) -> list[str]:
    motors = sorted(controller.motors)
    extra = controller.request.get("extra_delay_ticks", 0)
    source = where(controller)
    lines = [
        "// cartctl controller for the cart's control(): C99, also valid Arduino C++, float only.",
        "//",
        f"// Generated by: {command or 'cartctl export --arduino'}  (cartctl {__version__})",
        f"// From:         {source}, method {controller.method!r}, created {controller.created}",
    ]
    if controller.command:
        lines.append(f"// Designed by:  {controller.command}")
    lines += [
        f"// On model:     {controller.model_path} (sha256 {controller.model_sha256[:16]}...)",
        "//",
        f"// Assumes control() every {PERIOD_S:g} s (the template's 10 ms control thread) and "
        f"saturates the",
        f"// command at +-{controller.voltage_limit_v:g} V (the cart's supply is 12 V).",
        "//",
        "// The same difference equations and anti-windup as cartctl's runtime controller "
        "(cartctl.runtime),",
        "// computed in float.",
    ]
    uses_estimator = controller.method == "poles" or any(
        "estimator" in e for e in controller.motors.values()
    )
    if uses_estimator:
        lines += [
            "// The Kalman speed estimator runs its steady-state (fixed) gain L, as cartctl's does.",
        ]
        note = timing_noise_note(controller)
        if note is not None:
            lines.append(f"// Note: {note}.")
    lines += [
        "//",
        "// Delay: here the controller runs with one tick of delay (the voltage set at tick k "
        "reaches",
        "// the motor at tick k+1: nk = 2, the report's model); a PC-side loop over serial has "
        "several.",
    ]
    if isinstance(extra, int) and extra > 0:
        lines += [
            f"// This design assumed {extra} extra tick(s) of delay (--extra-delay {extra}, for a "
            "PC-side loop),",
            "// so on the cart it is conservative; design without --extra-delay for the cart "
            "itself.",
        ]
    lines += [
        "//",
        "// Motor A: the template's getSpeedMotorA() already carries motor A's sign flip, so a",
        "// positive voltage gives a positive speed on both motors.",
        "//",
        "// Use: save this file as cartctl_controller.h in the sketch folder (next to robot.cpp),",
        '// #include "cartctl_controller.h" in robot.cpp only, and in Robot::control():',
        "//",
        *_usage(motors),
        "//",
        "// Out channels: float 0/1 speed A/B (rad/s), 2/3 voltage A/B (V) as in the bridge sketch",
        f"// (firmware/cartctl_bridge), 4/5 reference A/B (rad/s), and {CH_FIRMWARE_ID} = "
        f"{ONBOARD_ID}, cartctl's on-board layout {ONBOARD_LAYOUT}:",
        "// by it 'cartctl monitor' names the channels (speed_a, voltage_a, reference_a, ...) "
        "itself, so",
        "// 'cartctl review', 'validate' and 'convert' read its CSV without --labels or --map.",
        "",
        "#ifndef CARTCTL_CONTROLLER_H",
        "#define CARTCTL_CONTROLLER_H",
        "",
        "#include <math.h>",
        "",
        f"#define CARTCTL_PERIOD_S {c_float(controller.period_s)}  /* tick period (s) */",
        f"#define CARTCTL_VOLTAGE_LIMIT_V {c_float(controller.voltage_limit_v)}  "
        "/* command saturation (V) */",
        f"#define CARTCTL_FIRMWARE_ID_CHANNEL {CH_FIRMWARE_ID}  /* out float channel of the id */",
        f"#define CARTCTL_FIRMWARE_ID {c_float(ONBOARD_ID)}  "
        f"/* cartctl's on-board channel layout {ONBOARD_LAYOUT} */",
        "",
    ]
    return lines


def arduino_source(controller: ControllerFile, *, command: str = "") -> str:
    """The controller as C for the course template's ``Robot::control()``.

    Per motor m in the file: a state struct ``cartctl_state_m_t`` with its instance
    ``cartctl_state_m``, ``void cartctl_reset_m(void)`` and
    ``float cartctl_step_m(float reference_rad_s, float measured_rad_s)`` returning the voltage.

    Parameters
    ----------
    controller : ControllerFile
        A loaded controller file (``pi`` or ``poles``).
    command : str
        The command line that asked for it, quoted in the header.

    Returns
    -------
    str
        The C source, ending with a newline.

    Raises
    ------
    InputError
        The controller was designed for another period than the cart's 10 ms.
    DataFileError
        A motor entry misses a key or holds numbers that do not make a controller.
    """
    if not math.isclose(controller.period_s, PERIOD_S, rel_tol=1e-9):
        raise InputError(
            f"{where(controller)} was designed for a period of {controller.period_s:g} s; the "
            f"cart's control() runs every {PERIOD_S:g} s, so design on a 10 ms model"
        )
    # the checks the loop applies (keys, gains, anti-windup) before any C is written
    build_controllers(as_steady_state(controller))
    lines = _header(controller, command)
    for motor in sorted(controller.motors):
        entry = controller.motors[motor]
        if controller.method == "pi":
            lines += pi_code(controller, motor, entry)
        else:
            lines += poles_code(controller, motor, entry)
    lines += ["#endif  /* CARTCTL_CONTROLLER_H */", ""]
    return "\n".join(lines)
