"""Commissioning, stage 5: ``cartctl run``'s closed-loop step on the cart, judged against the
tuning's prediction: overshoot ≤ max(:data:`TARGET_OVERSHOOT_PERCENT`, predicted nominal) + a
tolerance for the speed measured on, settling ≤ max(:data:`TARGET_SETTLING_S`, predicted
nominal + two ticks) (docs/commission.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cartctl.cart import encoder_quantum_rad_s
from cartctl.tune.grid import worst_metrics

STEP_RAD_S = 10.0
REFERENCE = f"step:{STEP_RAD_S:g}"
DURATION_S = 2.0
TARGET_OVERSHOOT_PERCENT = 5.0
TARGET_SETTLING_S = 0.15
TRUE_SPEED_TOLERANCE_PP = 1.0  # percentage points: the loop's own tick-to-tick spread


def run_argv(plant: str, controller: Path, out: Path, *, fast: bool,
             plant_options: Sequence[str] = ()) -> list[str]:  # fmt: skip
    """The ``cartctl run`` arguments of the verification step."""
    argv = ["run", "--plant", plant, "--controller", str(controller), "--reference", REFERENCE,
            "--duration", f"{DURATION_S:g}", "--rerun", "save", "--out", str(out),
            "--name", "verification", "--json", *plant_options]  # fmt: skip
    return argv + (["--fast"] if fast else [])


@dataclass(frozen=True)
class Verification:
    """Measured (worse of motors a and b; None: did not settle) against predicted (the tuning's
    ``nominal_…`` and ``worst_…`` figures), the pass ``limits`` with the ``speed`` judged, and the
    verdict."""

    measured: dict[str, float | None]
    predicted: dict[str, float | None]
    limits: dict[str, Any]
    passed: bool

    def to_dict(self) -> dict[str, Any]:
        return {"measured": self.measured, "predicted": self.predicted, "limits": self.limits,
                "pass": self.passed}  # fmt: skip


def compare(summary: dict[str, Any], predicted: dict[str, float | None],
            smoothed: dict[str, dict[str, Any]] | None = None) -> Verification:  # fmt: skip
    """Judge a ``cartctl run --json`` summary against the tuning's prediction (module docstring);
    ``smoothed`` per motor, the run's figures on the smoothed speed, judged where there is no true
    speed."""
    motors = summary.get("motors") or {}
    count_pp = 100.0 * encoder_quantum_rad_s() / STEP_RAD_S
    if summary.get("metrics_signal") == "true_speed":
        speed, tol = "true", TRUE_SPEED_TOLERANCE_PP
    elif smoothed:
        speed, tol = "smoothed", TRUE_SPEED_TOLERANCE_PP + 0.5 * count_pp
        motors = smoothed
    else:
        speed, tol = "encoder", count_pp
    worst = worst_metrics(motors)
    measured = {k: worst[k] for k in ("overshoot_percent", "settling_time_s")}
    nominal_os = predicted.get("nominal_overshoot_percent") or 0.0
    nominal_ts = predicted.get("nominal_settling_time_s") or 0.0
    max_os = max(TARGET_OVERSHOOT_PERCENT, nominal_os) + tol
    max_ts = max(TARGET_SETTLING_S, nominal_ts + 0.02)
    limits = {"overshoot_percent": max_os, "settling_time_s": max_ts, "speed": speed}
    os_, ts = measured["overshoot_percent"], measured["settling_time_s"]
    passed = os_ is not None and ts is not None and os_ <= max_os and ts <= max_ts
    return Verification(measured, dict(predicted), limits, bool(passed))
