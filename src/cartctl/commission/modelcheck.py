"""Commissioning, stage 3: identify both motors with a validation split, and judge the models.

ARX na = 2, nb = 3 (nb = 2 for a motor whose last term is within :data:`TAIL_SIGMAS` standard
deviations of zero: pole placement would cancel its zero with a gain ``run`` refuses), nk the
measured loop delay, estimated on the first :data:`SPLIT` of the excitation. A model passes on
the rest with a simulation fit ≥ :data:`MIN_FIT_PERCENT`, poles inside :data:`MAX_POLE_RADIUS`
and no residual–input cross-correlation beyond :data:`CROSS_CLEAR_FACTOR` × its 99 % bound;
whiteness is reported only (docs/commission.md says why).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cartctl.commission import StageError
from cartctl.data.trace import Trace
from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, identify

SPLIT = 0.7
NA, NB = 2, 3
MIN_FIT_PERCENT = 80.0
MAX_POLE_RADIUS = 0.99
CROSS_CLEAR_FACTOR = 2.0
TAIL_SIGMAS = 2.0


def request_for(loop_delay_ticks: int) -> IdentifyRequest:
    """The identification request for a loop of ``loop_delay_ticks`` (nk = that, at least 1)."""
    return IdentifyRequest(motors=("a", "b"), na=NA, nb=NB, delay=max(1, int(loop_delay_ticks)),
                           split=SPLIT)  # fmt: skip


@dataclass(frozen=True)
class MotorVerdict:
    """One motor's validation figures: simulation fit (%), largest pole radius, cross-correlation
    lags outside the 99 % bound of all lags, the largest over the bound, the whiteness test
    (reported only), and why the model fails (empty: it passes)."""

    fit_percent: float
    pole_radius: float
    cross_outside: int
    cross_lags: int
    cross_ratio: float
    white: bool
    problems: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"validation_fit_percent": self.fit_percent, "pole_radius": self.pole_radius,
                "cross_outside": self.cross_outside, "cross_lags": self.cross_lags,
                "cross_ratio": self.cross_ratio,
                "white": self.white, "passed": not self.problems,
                "problems": list(self.problems)}  # fmt: skip


def judge(result: IdentifyResult) -> dict[str, MotorVerdict]:
    """Each motor's verdict (the rules in the module docstring)."""
    out = {}
    for m, r in result.motors.items():
        fit = float(r.chosen.fit_simulation_percent)
        radius = float(r.chosen.model.pole_radius())
        d = r.diagnostics
        test = d.residuals.to_dict() if d is not None else {}
        cross = np.abs(np.asarray(test.get("cross", []), dtype=float))
        bound = float(test.get("cross_bound_99") or 0.0)
        cross_out, lags = int(np.count_nonzero(cross > bound)), int(cross.size)
        ratio = float(cross.max() / bound) if cross.size and bound > 0.0 else 0.0
        white = bool(test.get("white", False))
        problems = []
        if not fit >= MIN_FIT_PERCENT:
            problems.append(f"validation fit {fit:.1f} % < {MIN_FIT_PERCENT:g} %")
        if not radius < MAX_POLE_RADIUS:
            problems.append(f"a pole at |z| = {radius:.3f} (stable needs < {MAX_POLE_RADIUS:g})")
        if ratio > CROSS_CLEAR_FACTOR:
            problems.append(f"residuals correlated with the input (up to {ratio:.1f} × the 99 % "
                            "bound)")  # fmt: skip
        out[m] = MotorVerdict(fit, radius, cross_out, lags, ratio, white, tuple(problems))
    return out


def _noise_tail(fit: Any) -> bool:
    """The last numerator coefficient within :data:`TAIL_SIGMAS` standard deviations of zero."""
    b_last = float(fit.model.b[-1])
    std = np.asarray(fit.theta_std, dtype=float)
    return fit.model.nb > 1 and bool(np.isfinite(std[-1])) and abs(b_last) < TAIL_SIGMAS * std[-1]


def identify_and_judge(
    trace: Trace, loop_delay_ticks: int
) -> tuple[IdentifyResult, IdentifyRequest, dict[str, MotorVerdict]]:
    """Identify both motors, refit a noise tail with one term fewer, and judge."""
    request = request_for(loop_delay_ticks)
    result = identify([trace], request)
    short = tuple(m for m, r in result.motors.items() if _noise_tail(r.chosen))
    if short:
        again = identify([trace], replace(request, nb=NB - 1, motors=short))
        motors = {m: again.motors.get(m, r) for m, r in result.motors.items()}
        note = f"motor(s) {', '.join(short)}: nb = {NB - 1}, the last term being noise"
        result = IdentifyResult(result.period_s, motors, (*result.notes, note))
    return result, request, judge(result)


def verdict(verdicts: dict[str, MotorVerdict], excitation_v: float) -> None:
    """Raise :class:`StageError` naming the first failing motor and why (one line)."""
    for m, v in verdicts.items():
        if v.problems:
            raise StageError(
                f"identification: motor {m}'s model fails validation ({'; '.join(v.problems)}); "
                f"the {excitation_v:g} V excitation does not give a model to tune on: check the "
                "encoder (noise, loose cable) and that nothing touches the wheels"
            )
