"""C for one motor's controller (the PI or the state feedback, with its fixed-gain estimator),
for :mod:`cartctl.export.arduino`; the tests check it against the runtime with gcc."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from string import Template
from typing import Any

import numpy as np

from cartctl.design.controller_ss import feedback_gains, kalman_from_entry
from cartctl.design.controllerfile import ControllerFile
from cartctl.design.kalman import KalmanDesign
from cartctl.errors import DataFileError, InputError
from cartctl.runtime.pi import default_tracking_gain

_FLOAT32_MAX = float(np.finfo(np.float32).max)


def c_float(value: float) -> str:
    """A C ``float`` literal that parses to exactly ``float32(value)`` (nine significant digits;
    negative ones parenthesised for macros); InputError beyond a float32's range."""
    value = float(value)
    if not math.isfinite(value) or abs(value) > _FLOAT32_MAX:
        raise InputError(f"{value!r} does not fit in a C float (finite, |x| <= {_FLOAT32_MAX:g})")
    text = f"{float(np.float32(value)):.9g}"
    if not any(ch in text for ch in ".e"):
        text += ".0"
    return f"({text}f)" if text.startswith("-") else f"{text}f"


def where(controller: ControllerFile) -> str:
    return str(controller.path) if controller.path is not None else "controller file"


def _c_array(values: Sequence[float] | np.ndarray) -> str:
    return "{" + ", ".join(c_float(v) for v in values) + "}"


def _clamp(dest: str, value: str) -> str:
    lim = "CARTCTL_VOLTAGE_LIMIT_V"
    return f"{dest} = {value} > {lim} ? {lim} : ({value} < -{lim} ? -{lim} : {value});"


_ESTIMATOR = Template("""\
/* Kalman speed estimator, motor $m: $n states, x[0] the speed (rad/s)$bias. */
#define CARTCTL_${M}_STATES $n
static const float CARTCTL_${M}_EST_A[$n][$n] = $A;  /* state transition, per tick */
static const float CARTCTL_${M}_EST_B_RAD_S_PER_V[$n] = $B;
static const float CARTCTL_${M}_EST_C[$n] = $C;  /* y = C x */
static const float CARTCTL_${M}_EST_L[$n] = $L;  /* steady-state filter gain */

/* x += L (y - C x) with the speed measured at this tick (skipped when not finite);
 * returns the speed estimate x[0] (rad/s). */
static float cartctl_correct_$m(float measured_rad_s) {
  float *x = cartctl_state_$m.x;
  int i;
  if (isfinite(measured_rad_s)) {
    float innovation = measured_rad_s;
    for (i = 0; i < CARTCTL_${M}_STATES; ++i) {
      innovation -= CARTCTL_${M}_EST_C[i] * x[i];
    }
    for (i = 0; i < CARTCTL_${M}_STATES; ++i) {
      x[i] = x[i] + CARTCTL_${M}_EST_L[i] * innovation;
    }
  }
  return x[0];
}

/* x <- A x + B u with the voltage sent at this tick (V; not finite counts as 0 V). */
static void cartctl_predict_$m(float voltage_v) {
  float u = isfinite(voltage_v) ? voltage_v : 0.0f;
  float next[CARTCTL_${M}_STATES];
  int i, j;
  for (i = 0; i < CARTCTL_${M}_STATES; ++i) {
    float sum = 0.0f;
    for (j = 0; j < CARTCTL_${M}_STATES; ++j) {
      sum += CARTCTL_${M}_EST_A[i][j] * cartctl_state_$m.x[j];
    }
    next[i] = sum + CARTCTL_${M}_EST_B_RAD_S_PER_V[i] * u;
  }
  for (i = 0; i < CARTCTL_${M}_STATES; ++i) {
    cartctl_state_$m.x[i] = next[i];
  }
}
""")


def _estimator_code(motor: str, design: KalmanDesign) -> list[str]:
    """Constants, correct() and predict() of the fixed-gain Kalman estimator of one motor."""
    bias = ", the last one an input disturbance (V)" if design.has_bias else ""
    rows = ",\n    ".join(_c_array(row) for row in design.A)  # one row of A a line
    return _ESTIMATOR.substitute(
        m=motor, M=motor.upper(), n=design.A.shape[0], bias=bias, A=f"{{\n    {rows}\n}}",
        B=_c_array(design.B), C=_c_array(design.C), L=_c_array(design.L),
    ).split("\n")  # fmt: skip


def pi_code(controller: ControllerFile, motor: str, entry: Mapping[str, Any]) -> list[str]:
    """One motor's PI: the equations and anti-windup of :class:`PiController`."""
    m, M = motor, motor.upper()
    kp, ki = float(entry["kp"]), float(entry["ki"])
    mode = str(entry.get("anti_windup", "conditional"))
    kt = default_tracking_gain(kp, ki, controller.period_s)  # as PiController's
    est = entry.get("estimator")
    design = kalman_from_entry(est) if est is not None else None
    windup = {
        "conditional": _CONDITIONAL.substitute(clamp=_clamp("u_sat", "u")),
        "back-calculation": f"""\
    if (u_sat != u) {{  /* back-calculation: take the fraction Kt of the excess off */
      integral += CARTCTL_{M}_KT * (u_sat - u);
    }}
""",
    }.get(mode, "")
    kt_line = (
        f"#define CARTCTL_{M}_KT {c_float(kt)}  /* tracking gain per tick: the fraction of the "
        "excess over the limit taken off the integral */\n"
        if mode == "back-calculation"
        else ""
    )
    n = 0 if design is None else design.A.shape[0]
    return _PI.substitute(
        m=m, M=M, mode=mode, on_estimate=", on a Kalman speed estimate" if design else "",
        kp=c_float(kp), ki_ts=c_float(ki * controller.period_s), ki=f"{ki:.6g}",
        kt=kt_line,
        x=f"  float x[{n}];            /* the estimator's state */\n" if design else "",
        estimator="\n".join(_estimator_code(motor, design)) + "\n" if design else "",
        at_rest=", estimator at rest" if design else "",
        reset_x=_RESET_X.substitute(M=M, m=m) if design else "",
        correct=f"  if (isfinite(y)) {{\n    y = cartctl_correct_{m}(y);\n  }}\n" if design else "",
        clamp=_clamp("u_sat", "u"), windup=windup,
        predict=f"  cartctl_predict_{m}(u_sat);\n" if design else "",
    ).split("\n")  # fmt: skip


_PI = Template("""\
/* ---- motor $m: PI, anti-windup $mode$on_estimate ---- */
#define CARTCTL_${M}_KP_V_PER_RAD_S $kp
#define CARTCTL_${M}_KI_TS_V_PER_RAD_S $ki_ts  /* Ki*Ts, Ki = $ki V/rad: the integral's gain per tick */
${kt}
typedef struct {
  float integral_v;      /* I, the integral term (V) */
  float estimate_rad_s;  /* the speed the PI acted on at the last tick (rad/s) */
${x}} cartctl_state_${m}_t;

cartctl_state_${m}_t cartctl_state_$m;

${estimator}/* Back to rest: integral 0$at_rest. */
void cartctl_reset_$m(void) {
  cartctl_state_$m.integral_v = 0.0f;
  cartctl_state_$m.estimate_rad_s = 0.0f;
${reset_x}}

/* One tick: the voltage (V) to set for motor $M, within +-CARTCTL_VOLTAGE_LIMIT_V.
 * 0 V, with the integral unchanged, when the reference or the measurement is not finite. */
float cartctl_step_$m(float reference_rad_s, float measured_rad_s) {
  cartctl_state_${m}_t *s = &cartctl_state_$m;
  float y = measured_rad_s;
  float e, integral, p, u, u_sat;
${correct}  s->estimate_rad_s = y;
  e = reference_rad_s - y;
  integral = s->integral_v + CARTCTL_${M}_KI_TS_V_PER_RAD_S * e;
  p = CARTCTL_${M}_KP_V_PER_RAD_S * e;
  u = p + integral;
  u_sat = 0.0f;
  if (isfinite(u)) {  /* not finite: a NaN/inf input, or an overflow -> 0 V */
    $clamp
${windup}    s->integral_v = integral;
  }
${predict}  return u_sat;
}
""")
_RESET_X = Template("""\
  {
    int i;
    for (i = 0; i < CARTCTL_${M}_STATES; ++i) {
      cartctl_state_$m.x[i] = 0.0f;
    }
  }
""")
_CONDITIONAL = Template("""\
    if (u_sat != u && e * u > 0.0f) {
      /* conditional integration: the integral moves at most up to the value that
       * puts the output on the limit, and never back */
      float old = s->integral_v;
      float edge = u_sat - p;
      if (e > 0.0f) {
        float lower = edge < integral ? edge : integral;
        integral = lower > old ? lower : old;
      } else {
        float upper = edge > integral ? edge : integral;
        integral = upper < old ? upper : old;
      }
      u = p + integral;
      $clamp
    }
""")


def poles_code(controller: ControllerFile, motor: str, entry: Mapping[str, Any]) -> list[str]:
    """One motor's state feedback: the equations of :class:`StateFeedbackController`."""
    gains = feedback_gains(entry, controller.period_s)
    n, m = gains.K.size, gains.estimator.A.shape[0]
    if not 1 <= n <= m or not np.all(np.isfinite(gains.K)):
        raise DataFileError(
            where(controller),
            f"[motors.{motor}] K must hold 1..{m} finite gains (one per model state), got {n}",
        )
    return _POLES.substitute(
        m=motor, M=motor.upper(), n=n, states=m, K=_c_array(gains.K), Ki=c_float(gains.Ki),
        Kr=c_float(gains.Kr), estimator="\n".join(_estimator_code(motor, gains.estimator)),
        clamp=_clamp("u", "u_raw"),
    ).split("\n")  # fmt: skip


_POLES = Template("""\
/* ---- motor $m: pole placement, state feedback with integral action on a Kalman estimate ---- */
#define CARTCTL_${M}_FEEDBACK_STATES $n
static const float CARTCTL_${M}_K[$n] = $K;  /* V per unit of each model state (rad/s) */
#define CARTCTL_${M}_KI_V_PER_RAD $Ki  /* on the integral of (r - y) */
#define CARTCTL_${M}_KR_V_PER_RAD_S $Kr  /* reference feedforward */

typedef struct {
  float x[$states];            /* the estimator's state: x[0] the speed (rad/s) */
  float integral_rad;    /* x_i, the integral of (r - y) (rad) */
  float estimate_rad_s;  /* the speed estimate the last step acted on (rad/s) */
  int saturated;         /* whether the last command hit the limit */
} cartctl_state_${m}_t;

cartctl_state_${m}_t cartctl_state_$m;

$estimator
/* Integrator cleared, estimator at rest. */
void cartctl_reset_$m(void) {
  int i;
  for (i = 0; i < CARTCTL_${M}_STATES; ++i) {
    cartctl_state_$m.x[i] = 0.0f;
  }
  cartctl_state_$m.integral_rad = 0.0f;
  cartctl_state_$m.estimate_rad_s = 0.0f;
  cartctl_state_$m.saturated = 0;
}

/* One tick: the voltage (V) to set for motor $M, within +-CARTCTL_VOLTAGE_LIMIT_V.
 * 0 V when the reference or the measurement is not finite (the integrator holds), and
 * 0 V plus a reset when the command overflows. */
float cartctl_step_$m(float reference_rad_s, float measured_rad_s) {
  cartctl_state_${m}_t *s = &cartctl_state_$m;
  float u_raw, u, error;
  int j;
  if (!isfinite(measured_rad_s) || !isfinite(reference_rad_s)) {
    s->estimate_rad_s = cartctl_correct_$m(measured_rad_s);  /* skips a non-finite y */
    s->saturated = 0;
    cartctl_predict_$m(0.0f);
    return 0.0f;
  }
  s->estimate_rad_s = cartctl_correct_$m(measured_rad_s);
  u_raw = CARTCTL_${M}_KR_V_PER_RAD_S * reference_rad_s - CARTCTL_${M}_KI_V_PER_RAD * s->integral_rad;
  for (j = 0; j < CARTCTL_${M}_FEEDBACK_STATES; ++j) {
    u_raw -= CARTCTL_${M}_K[j] * s->x[j];
  }
  if (!isfinite(u_raw)) {  /* overflowed on an absurd value: 0 V and start afresh */
    cartctl_reset_$m();
    cartctl_predict_$m(0.0f);
    return 0.0f;
  }
  $clamp
  s->saturated = u != u_raw;
  error = reference_rad_s - measured_rad_s;
  /* the integrator moves u by -Ki*Ts*error next tick: hold it if that deepens saturation */
  if (!s->saturated || ((u_raw > u) != (-CARTCTL_${M}_KI_V_PER_RAD * error > 0.0f))) {
    s->integral_rad += CARTCTL_PERIOD_S * error;
  }
  cartctl_predict_$m(u);
  return u;
}
""")
