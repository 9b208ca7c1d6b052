"""A designed controller as C for the cart's ``control()`` (the course template on microOS).

Where it sits: after ``design``; ``cartctl export CONTROLLER.toml --arduino`` prints what
:func:`arduino_source` returns. The C runs the same difference equations, anti-windup and estimator
as the runtime controllers (:class:`~cartctl.runtime.pi.PiController`,
:class:`~cartctl.runtime.statefeedback.StateFeedbackController`), line for line and in ``float``
(the Arduino Mega has no wider type), with these differences:

- the Kalman estimator always runs its steady-state (fixed) gain L, as
  :class:`~cartctl.runtime.kalman.SteadyStateSpeedEstimator` does; compare it with the runtime
  controller of :func:`as_steady_state`;
- float32 arithmetic: the voltages agree with the runtime's to within 1e-4 of the voltage range
  (a few µV for the PI; up to 0.2 mV for state feedback, which sums terms of tens of volts), and
  values beyond 3.4e38 overflow sooner (a command that overflows gives 0 V on both).

The text is C99 that is also valid C++ (the template compiles ``robot.cpp`` as C++), uses only
``<math.h>`` (``isfinite``), and is deterministic: the same file gives the same text.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cartctl import __version__
from cartctl.cart import PERIOD_S
from cartctl.design.build import build_controllers
from cartctl.design.controllerfile import ControllerFile, load_controller
from cartctl.design.entries import kalman_from_entry
from cartctl.design.kalman import KalmanDesign
from cartctl.errors import DataFileError, InputError
from cartctl.runtime.base import Controller

__all__ = ["CART_PERIOD_S", "arduino_source", "as_steady_state", "c_float"]

CART_PERIOD_S = PERIOD_S
"""The period of the template's control thread (s): ``control()`` runs every 10 ms."""

_FLOAT32_MAX = float(np.finfo(np.float32).max)


def c_float(value: float) -> str:
    """A C ``float`` literal that parses to exactly ``float32(value)``.

    Nine significant digits identify a float32 uniquely; negative literals are parenthesised so
    they are safe inside macros.

    Raises
    ------
    InputError
        ``value`` is not finite or does not fit in a float32.
    """
    value = float(value)
    if not math.isfinite(value) or abs(value) > _FLOAT32_MAX:
        raise InputError(f"{value!r} does not fit in a C float (finite, |x| <= {_FLOAT32_MAX:g})")
    text = f"{float(np.float32(value)):.9g}"
    if not any(ch in text for ch in ".e"):
        text += ".0"
    return f"({text}f)" if text.startswith("-") else f"{text}f"


def as_steady_state(controller: ControllerFile) -> ControllerFile:
    """The same controller file, asking for the fixed-gain estimator (what the C runs)."""
    return dataclasses.replace(
        controller, request={**controller.request, "estimator_gain": "steady-state"}
    )


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


def _where(controller: ControllerFile) -> str:
    return str(controller.path) if controller.path is not None else "controller file"


def _estimator(controller: ControllerFile, motor: str, entry: Mapping[str, Any]) -> KalmanDesign:
    """The estimator of one motor, its arrays checked for the shapes the C code indexes."""
    path = controller.path or "controller file"
    try:
        design = kalman_from_entry(entry)
    except KeyError as exc:
        raise DataFileError(path, f"[motors.{motor}] misses {exc.args[0]}") from None
    except (TypeError, ValueError) as exc:
        raise DataFileError(path, f"[motors.{motor}.estimator]: {exc}") from None
    m = design.A.shape[0] if design.A.ndim == 2 else -1
    shapes = {"A": (m, m), "B": (m,), "C": (m,), "L": (m,)}
    for name, shape in shapes.items():
        array = getattr(design, name)
        if m < 1 or array.shape != shape or not np.all(np.isfinite(array)):
            raise DataFileError(
                path,
                f"[motors.{motor}.estimator] {name} must be a finite array of shape {shape} "
                f"(m = the number of states), got shape {array.shape}",
            )
    return design


def _c_array(values: Sequence[float]) -> str:
    return "{" + ", ".join(c_float(v) for v in values) + "}"


def _c_matrix(rows: np.ndarray, indent: str) -> str:
    inner = f",\n{indent}    ".join(_c_array(row) for row in rows)
    return "{\n" + f"{indent}    {inner}\n{indent}}}"


def _clamp(dest: str, value: str) -> str:
    lim = "CARTCTL_VOLTAGE_LIMIT_V"
    return f"{dest} = {value} > {lim} ? {lim} : ({value} < -{lim} ? -{lim} : {value});"


def _estimator_code(motor: str, design: KalmanDesign) -> list[str]:
    """Constants, correct() and predict() of the fixed-gain Kalman estimator of one motor."""
    up = motor.upper()
    m = design.A.shape[0]
    state = f"cartctl_state_{motor}"
    return [
        f"/* Kalman speed estimator, motor {motor}: {m} states, x[0] the speed (rad/s)"
        + (", the last one an input disturbance (V)" if design.has_bias else "")
        + ". */",
        f"#define CARTCTL_{up}_STATES {m}",
        f"static const float CARTCTL_{up}_EST_A[{m}][{m}] = "
        f"{_c_matrix(design.A, '')};  /* state transition, per tick */",
        f"static const float CARTCTL_{up}_EST_B_RAD_S_PER_V[{m}] = {_c_array(design.B)};",
        f"static const float CARTCTL_{up}_EST_C[{m}] = {_c_array(design.C)};  /* y = C x */",
        f"static const float CARTCTL_{up}_EST_L[{m}] = "
        f"{_c_array(design.L)};  /* steady-state filter gain */",
        "",
        "/* x += L (y - C x) with the speed measured at this tick (skipped when not finite);",
        " * returns the speed estimate x[0] (rad/s). */",
        f"static float cartctl_correct_{motor}(float measured_rad_s) {{",
        f"  float *x = {state}.x;",
        "  int i;",
        "  if (isfinite(measured_rad_s)) {",
        "    float innovation = measured_rad_s;",
        f"    for (i = 0; i < CARTCTL_{up}_STATES; ++i) {{",
        f"      innovation -= CARTCTL_{up}_EST_C[i] * x[i];",
        "    }",
        f"    for (i = 0; i < CARTCTL_{up}_STATES; ++i) {{",
        f"      x[i] = x[i] + CARTCTL_{up}_EST_L[i] * innovation;",
        "    }",
        "  }",
        "  return x[0];",
        "}",
        "",
        "/* x <- A x + B u with the voltage sent at this tick (V; not finite counts as 0 V). */",
        f"static void cartctl_predict_{motor}(float voltage_v) {{",
        "  float u = isfinite(voltage_v) ? voltage_v : 0.0f;",
        f"  float next[CARTCTL_{up}_STATES];",
        "  int i, j;",
        f"  for (i = 0; i < CARTCTL_{up}_STATES; ++i) {{",
        "    float sum = 0.0f;",
        f"    for (j = 0; j < CARTCTL_{up}_STATES; ++j) {{",
        f"      sum += CARTCTL_{up}_EST_A[i][j] * {state}.x[j];",
        "    }",
        f"    next[i] = sum + CARTCTL_{up}_EST_B_RAD_S_PER_V[i] * u;",
        "  }",
        f"  for (i = 0; i < CARTCTL_{up}_STATES; ++i) {{",
        f"    {state}.x[i] = next[i];",
        "  }",
        "}",
        "",
    ]


def _pi_code(controller: ControllerFile, motor: str, entry: Mapping[str, Any]) -> list[str]:
    """One motor's PI: the equations and anti-windup of :class:`PiController`."""
    up = motor.upper()
    kp, ki = float(entry["kp"]), float(entry["ki"])
    mode = str(entry.get("anti_windup", "conditional"))
    period_s = controller.period_s
    # the same defaults as PiController: Ki·Ts per tick, tracking gain min(1, Ts·Ki/Kp)
    ki_ts = ki * period_s
    kt = min(1.0, period_s * ki / kp) if kp > 0.0 else 1.0
    est = entry.get("estimator")
    design = _estimator(controller, motor, est) if est is not None else None
    state = f"cartctl_state_{motor}"
    lines = [
        f"/* ---- motor {motor}: PI, anti-windup {mode}"
        + (", on a Kalman speed estimate" if design else "")
        + " ---- */",
        f"#define CARTCTL_{up}_KP_V_PER_RAD_S {c_float(kp)}",
        f"#define CARTCTL_{up}_KI_TS_V_PER_RAD_S {c_float(ki_ts)}  "
        f"/* Ki*Ts, Ki = {ki:.6g} V/rad: the integral's gain per tick */",
    ]
    if mode == "back-calculation":
        lines.append(
            f"#define CARTCTL_{up}_KT {c_float(kt)}  /* tracking gain per tick: the fraction of "
            "the excess over the limit taken off the integral */"
        )
    lines += [
        "",
        "typedef struct {",
        "  float integral_v;      /* I, the integral term (V) */",
        "  float estimate_rad_s;  /* the speed the PI acted on at the last tick (rad/s) */",
    ]
    if design is not None:
        lines.append(f"  float x[{design.A.shape[0]}];            /* the estimator's state */")
    lines += [
        f"}} cartctl_state_{motor}_t;",
        "",
        f"cartctl_state_{motor}_t {state};",
        "",
    ]
    if design is not None:
        lines += _estimator_code(motor, design)
    lines += [
        f"/* Back to rest: integral 0{', estimator at rest' if design else ''}. */",
        f"void cartctl_reset_{motor}(void) {{",
        f"  {state}.integral_v = 0.0f;",
        f"  {state}.estimate_rad_s = 0.0f;",
    ]
    if design is not None:
        lines += [
            "  {",
            "    int i;",
            f"    for (i = 0; i < CARTCTL_{up}_STATES; ++i) {{",
            f"      {state}.x[i] = 0.0f;",
            "    }",
            "  }",
        ]
    lines += [
        "}",
        "",
        "/* One tick: the voltage (V) to set for motor "
        f"{motor.upper()}, within +-CARTCTL_VOLTAGE_LIMIT_V.",
        " * 0 V, with the integral unchanged, when the reference or the measurement is not finite. */",
        f"float cartctl_step_{motor}(float reference_rad_s, float measured_rad_s) {{",
        f"  cartctl_state_{motor}_t *s = &{state};",
        "  float y = measured_rad_s;",
        "  float e, integral, p, u, u_sat;",
    ]
    if design is not None:
        lines += ["  if (isfinite(y)) {", f"    y = cartctl_correct_{motor}(y);", "  }"]
    lines += [
        "  s->estimate_rad_s = y;",
        "  e = reference_rad_s - y;",
        f"  integral = s->integral_v + CARTCTL_{up}_KI_TS_V_PER_RAD_S * e;",
        f"  p = CARTCTL_{up}_KP_V_PER_RAD_S * e;",
        "  u = p + integral;",
        "  u_sat = 0.0f;",
        "  if (isfinite(u)) {  /* not finite: a NaN/inf input, or an overflow -> 0 V */",
        "    " + _clamp("u_sat", "u"),
    ]
    if mode == "conditional":
        lines += [
            "    if (u_sat != u && e * u > 0.0f) {",
            "      /* conditional integration: the integral moves at most up to the value that",
            "       * puts the output on the limit, and never back */",
            "      float old = s->integral_v;",
            "      float edge = u_sat - p;",
            "      if (e > 0.0f) {",
            "        float lower = edge < integral ? edge : integral;",
            "        integral = lower > old ? lower : old;",
            "      } else {",
            "        float upper = edge > integral ? edge : integral;",
            "        integral = upper < old ? upper : old;",
            "      }",
            "      u = p + integral;",
            "      " + _clamp("u_sat", "u"),
            "    }",
        ]
    elif mode == "back-calculation":
        lines += [
            "    if (u_sat != u) {  /* back-calculation: take the fraction Kt of the excess off */",
            f"      integral += CARTCTL_{up}_KT * (u_sat - u);",
            "    }",
        ]
    lines += ["    s->integral_v = integral;", "  }"]
    if design is not None:
        lines.append(f"  cartctl_predict_{motor}(u_sat);")
    lines += ["  return u_sat;", "}", ""]
    return lines


def _poles_code(controller: ControllerFile, motor: str, entry: Mapping[str, Any]) -> list[str]:
    """One motor's state feedback: the equations of :class:`StateFeedbackController`."""
    up = motor.upper()
    path = controller.path or "controller file"
    design = _estimator(controller, motor, entry["estimator"])
    gains = np.asarray(entry["K"], dtype=float).ravel()
    n, m = gains.size, design.A.shape[0]
    if not 1 <= n <= m or not np.all(np.isfinite(gains)):
        raise DataFileError(
            path, f"[motors.{motor}] K must hold 1..{m} finite gains (one per model state), got {n}"
        )
    state = f"cartctl_state_{motor}"
    lines = [
        f"/* ---- motor {motor}: pole placement, state feedback with integral action on a "
        "Kalman estimate ---- */",
        f"#define CARTCTL_{up}_FEEDBACK_STATES {n}",
        f"static const float CARTCTL_{up}_K[{n}] = {_c_array(gains)};  "
        "/* V per unit of each model state (rad/s) */",
        f"#define CARTCTL_{up}_KI_V_PER_RAD {c_float(float(entry['Ki']))}  "
        "/* on the integral of (r - y) */",
        f"#define CARTCTL_{up}_KR_V_PER_RAD_S {c_float(float(entry['Kr']))}  "
        "/* reference feedforward */",
        "",
        "typedef struct {",
        f"  float x[{m}];            /* the estimator's state: x[0] the speed (rad/s) */",
        "  float integral_rad;    /* x_i, the integral of (r - y) (rad) */",
        "  float estimate_rad_s;  /* the speed estimate the last step acted on (rad/s) */",
        "  int saturated;         /* whether the last command hit the limit */",
        f"}} cartctl_state_{motor}_t;",
        "",
        f"cartctl_state_{motor}_t {state};",
        "",
        *_estimator_code(motor, design),
        "/* Integrator cleared, estimator at rest. */",
        f"void cartctl_reset_{motor}(void) {{",
        "  int i;",
        f"  for (i = 0; i < CARTCTL_{up}_STATES; ++i) {{",
        f"    {state}.x[i] = 0.0f;",
        "  }",
        f"  {state}.integral_rad = 0.0f;",
        f"  {state}.estimate_rad_s = 0.0f;",
        f"  {state}.saturated = 0;",
        "}",
        "",
        f"/* One tick: the voltage (V) to set for motor {motor.upper()}, within "
        "+-CARTCTL_VOLTAGE_LIMIT_V.",
        " * 0 V when the reference or the measurement is not finite (the integrator holds), and",
        " * 0 V plus a reset when the command overflows. */",
        f"float cartctl_step_{motor}(float reference_rad_s, float measured_rad_s) {{",
        f"  cartctl_state_{motor}_t *s = &{state};",
        "  float u_raw, u, error;",
        "  int j;",
        "  if (!isfinite(measured_rad_s) || !isfinite(reference_rad_s)) {",
        f"    s->estimate_rad_s = cartctl_correct_{motor}(measured_rad_s);"
        "  /* skips a non-finite y */",
        "    s->saturated = 0;",
        f"    cartctl_predict_{motor}(0.0f);",
        "    return 0.0f;",
        "  }",
        f"  s->estimate_rad_s = cartctl_correct_{motor}(measured_rad_s);",
        f"  u_raw = CARTCTL_{up}_KR_V_PER_RAD_S * reference_rad_s"
        f" - CARTCTL_{up}_KI_V_PER_RAD * s->integral_rad;",
        f"  for (j = 0; j < CARTCTL_{up}_FEEDBACK_STATES; ++j) {{",
        f"    u_raw -= CARTCTL_{up}_K[j] * s->x[j];",
        "  }",
        "  if (!isfinite(u_raw)) {  /* overflowed on an absurd value: 0 V and start afresh */",
        f"    cartctl_reset_{motor}();",
        f"    cartctl_predict_{motor}(0.0f);",
        "    return 0.0f;",
        "  }",
        "  " + _clamp("u", "u_raw"),
        "  s->saturated = u != u_raw;",
        "  error = reference_rad_s - measured_rad_s;",
        "  /* the integrator moves u by -Ki*Ts*error next tick: hold it if that deepens saturation */",
        f"  if (!s->saturated || ((u_raw > u) != (-CARTCTL_{up}_KI_V_PER_RAD * error > 0.0f))) {{",
        "    s->integral_rad += CARTCTL_PERIOD_S * error;",
        "  }",
        f"  cartctl_predict_{motor}(u);",
        "  return u;",
        "}",
        "",
    ]
    return lines


def _usage(motors: Sequence[str]) -> list[str]:
    """The header's example of ``Robot::control()`` for the motors present."""
    lines = ["  void Robot::control() {"]
    channel = {"a": 0, "b": 1}
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
    outputs = (("speed_{}_rad_s", 0), ("voltage_{}_v", 2), ("reference_{}_rad_s", 4))
    for name, first in outputs:
        for m in motors:
            lines.append(f"    writeFloat({first + channel[m]}, {name.format(m)});")
    lines[-len(outputs) * len(motors)] += "  // out to the PC: cartctl monitor, QRC"
    lines.append("  }")
    return ["//" + (" " + line if line else "") for line in lines]


def _header(controller: ControllerFile, command: str) -> list[str]:
    motors = sorted(controller.motors)
    extra = controller.request.get("extra_delay_ticks", 0)
    source = _where(controller)
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
        f"// Assumes control() every {CART_PERIOD_S:g} s (the template's 10 ms control thread) and "
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
            "// The Kalman speed estimator runs its steady-state (fixed) gain L, like cartctl's",
            "// '--estimator-gain steady-state'; cartctl's default filterpy filter converges to the "
            "same L.",
        ]
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
        "// Out channels: float 0/1 speed A/B (rad/s) and 2/3 voltage A/B (V), as in the bridge "
        "sketch",
        "// (firmware/cartctl_bridge), and 4/5 reference A/B (rad/s).",
        "",
        "#ifndef CARTCTL_CONTROLLER_H",
        "#define CARTCTL_CONTROLLER_H",
        "",
        "#include <math.h>",
        "",
        f"#define CARTCTL_PERIOD_S {c_float(controller.period_s)}  /* tick period (s) */",
        f"#define CARTCTL_VOLTAGE_LIMIT_V {c_float(controller.voltage_limit_v)}  "
        "/* command saturation (V) */",
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
    if not math.isclose(controller.period_s, CART_PERIOD_S, rel_tol=1e-9):
        raise InputError(
            f"{_where(controller)} was designed for a period of {controller.period_s:g} s; the "
            f"cart's control() runs every {CART_PERIOD_S:g} s, so design on a 10 ms model"
        )
    # the checks the loop applies (keys, gains, anti-windup) before any C is written
    build_controllers(as_steady_state(controller))
    lines = _header(controller, command)
    for motor in sorted(controller.motors):
        entry = controller.motors[motor]
        if controller.method == "pi":
            lines += _pi_code(controller, motor, entry)
        else:
            lines += _poles_code(controller, motor, entry)
    lines += ["#endif  /* CARTCTL_CONTROLLER_H */", ""]
    return "\n".join(lines)
