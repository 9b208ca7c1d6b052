"""Commissioning, stage 5: a closed-loop step on the cart, measured against the prediction.

The step is ``cartctl run`` itself (run in process by the command that drives commissioning: the
chosen controller, ``step:10`` for 2 s,
the same plant; ``--fast`` where the plant is simulated), so what commissioning verified is what
the user will run. :func:`compare` judges it (pure): the worse of motors a and b must have

- overshoot ≤ max(:data:`TARGET_OVERSHOOT_PERCENT`, the predicted nominal overshoot) + a
  tolerance that depends on the speed measured: :data:`TRUE_SPEED_TOLERANCE_PP` on a simulator's
  true speed; on a cart, the run's RTS-smoothed speed (``motors.<m>.smoothed`` of its summary,
  the encoder speed blurred by a whole count being no measure of a few percent) with half an
  encoder count per tick over the step more (the smoother's error is at most about half a count);
  one whole count (3.5 % of 10 rad/s) on the bare encoder speed, where the run gives nothing else;
- settling ≤ max(:data:`TARGET_SETTLING_S`, the predicted nominal settling + two ticks).

The predicted figures are the tuning's for the chosen setting (nominal: the loop on the model;
worst: over its sampled and timing plants), shown beside the measured ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cartctl.cart import encoder_quantum_rad_s

STEP_RAD_S = 10.0
REFERENCE = f"step:{STEP_RAD_S:g}"
DURATION_S = 2.0
TARGET_OVERSHOOT_PERCENT = 5.0
TARGET_SETTLING_S = 0.15
TRUE_SPEED_TOLERANCE_PP = 1.0
"""Overshoot tolerance (percentage points) on a true speed: the loop's own tick-to-tick spread."""


def run_argv(plant: str, controller: Path, out: Path, *, fast: bool,
             plant_options: Sequence[str] = ()) -> list[str]:  # fmt: skip
    """The ``cartctl run`` arguments of the verification step."""
    argv = ["run", "--plant", plant, "--controller", str(controller), "--reference", REFERENCE,
            "--duration", f"{DURATION_S:g}", "--rerun", "save", "--out", str(out),
            "--name", "verification", "--json", *plant_options]  # fmt: skip
    return argv + (["--fast"] if fast else [])


@dataclass(frozen=True)
class Verification:
    """Measured against predicted, and the verdict.

    Attributes
    ----------
    measured : dict
        ``overshoot_percent`` and ``settling_time_s``, the worse of motors a and b (None: did not
        settle).
    predicted : dict
        The tuning's ``nominal_…`` and ``worst_…`` figures of the chosen setting.
    limits : dict
        The pass bounds (``overshoot_percent``, ``settling_time_s``) and the ``speed`` measured on.
    passed : bool
    """

    measured: dict[str, float | None]
    predicted: dict[str, float | None]
    limits: dict[str, Any]
    passed: bool

    def to_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {"measured": self.measured, "predicted": self.predicted, "limits": self.limits,
                "pass": self.passed}  # fmt: skip


def _worse(motors: dict[str, dict[str, Any]], key: str) -> float | None:
    values = [m.get(key) for m in motors.values()]
    known = [float(v) for v in values if v is not None]
    if len(known) < len(values):
        return None
    return max(known)


def compare(summary: dict[str, Any], predicted: dict[str, float | None],
            smoothed: dict[str, dict[str, Any]] | None = None) -> Verification:  # fmt: skip
    """Judge a ``cartctl run --json`` summary against the tuning's prediction (module docstring).

    ``smoothed``: per motor, the run's figures on the smoothed speed (``motors.<m>.smoothed`` of
    its summary), judged instead of the encoder's where the run has no true speed.
    """
    motors = summary.get("motors") or {}
    count_pp = 100.0 * encoder_quantum_rad_s() / STEP_RAD_S
    if summary.get("metrics_signal") == "true_speed":
        speed, tol = "true", TRUE_SPEED_TOLERANCE_PP
    elif smoothed:
        speed, tol = "smoothed", TRUE_SPEED_TOLERANCE_PP + 0.5 * count_pp
        motors = smoothed
    else:
        speed, tol = "encoder", count_pp
    measured = {k: _worse(motors, k) for k in ("overshoot_percent", "settling_time_s")}
    nominal_os = predicted.get("nominal_overshoot_percent") or 0.0
    nominal_ts = predicted.get("nominal_settling_time_s") or 0.0
    max_os = max(TARGET_OVERSHOOT_PERCENT, nominal_os) + tol
    max_ts = max(TARGET_SETTLING_S, nominal_ts + 0.02)
    limits = {"overshoot_percent": max_os, "settling_time_s": max_ts, "speed": speed}
    os_, ts = measured["overshoot_percent"], measured["settling_time_s"]
    passed = os_ is not None and ts is not None and os_ <= max_os and ts <= max_ts
    return Verification(measured, dict(predicted), limits, bool(passed))
