"""Input-delay estimation: which nk lets the ARX structure explain the data best.

The report assumes nk = 2 (one sample from the zero-order hold, one from microOS); a PC-side loop
over serial adds ticks. Every candidate is fitted on the same equations and the smallest
equation-error loss wins. Both motors share one loop, so :func:`joint_delay` picks one delay from
their joint evidence and says when the best candidates are too close to call.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cartctl.cart import PERIOD_S
from cartctl.errors import InputError
from cartctl.identification.arx import (
    IdentificationError,
    Segment,
    as_segments,
    check_orders,
    first_row,
    fit_arx,
)


@dataclass(frozen=True)
class DelayEstimate:
    """One motor's delay evidence: per candidate the equation-error RMS (rad/s) of its ARX fit on
    the same ``equations`` and its fits (%; the simulation fit NaN for an unstable model).

    ``nk`` is this motor's best, or the joint choice (:func:`joint_delay`), and then
    ``nk_alone`` is this motor's own best where it differs.
    """

    nk: int
    candidates: tuple[int, ...]
    residual_rms: tuple[float, ...]
    fit_prediction_percent: tuple[float, ...]
    fit_simulation_percent: tuple[float, ...]
    equations: int = 0
    nk_alone: int | None = None

    def to_dict(self) -> dict[str, Any]:
        keys = ("nk", "residual_rms", "fit_prediction_percent", "fit_simulation_percent")
        rows = zip(self.candidates, self.residual_rms, self.fit_prediction_percent,
                   self.fit_simulation_percent, strict=True)  # fmt: skip
        return {
            "nk": self.nk,
            "nk_alone": self.nk if self.nk_alone is None else self.nk_alone,
            "equations": self.equations,
            "candidates": [dict(zip(keys, row, strict=True)) for row in rows],
        }


INDISTINCT_FRACTION = 1e-3
"""Candidates whose equation errors all lie within this fraction of the best cannot be told apart."""


def check_distinct(estimates: Mapping[str, DelayEstimate]) -> None:
    """Refuse evidence whose candidates' equation errors all lie within
    :data:`INDISTINCT_FRACTION` of the best, for every motor: the data does not show the delay."""
    flat = []
    for est in estimates.values():
        rms = np.asarray(est.residual_rms)
        if len(rms) < 2 or rms.max() > (1.0 + INDISTINCT_FRACTION) * rms.min():
            return
        flat.append(rms.min())
    if flat:
        cands = next(iter(estimates.values())).candidates
        raise IdentificationError(
            f"--delay auto cannot tell: the equation errors of nk = "
            f"{', '.join(map(str, cands))} are within {INDISTINCT_FRACTION:.1%} of each other "
            f"({min(flat):.4g} rad/s); the data does not show when the motor answers, so give "
            "--delay N (2 on board, loop delay + 1 over serial)"
        )


def delay_evidence(
    segments: Sequence[Segment],
    *,
    na: int = 2,
    nb: int = 2,
    candidates: Sequence[int] = range(1, 7),
    period_s: float = PERIOD_S,
    eval_segments: Sequence[Segment] | None = None,
) -> DelayEstimate:
    """Fit every candidate delay (samples) on common equations: the evidence, and this motor's
    best (smallest equation error; ties up to 1e-9 of the output's RMS to the smaller delay).

    ``eval_segments`` is the raw data for the simulation fits when ``segments`` is prefiltered.
    Nothing is refused for being too close (:func:`check_distinct` does that).
    """
    cands = tuple(int(c) for c in candidates)
    if not cands:
        raise InputError("no candidate delays to try")
    for c in cands:
        check_orders(na, nb, c)
    data = as_segments(segments)
    start = max(first_row(na, nb, c) for c in cands)
    fits = []
    for c in cands:
        try:
            fits.append(fit_arx(data, na=na, nb=nb, nk=c, period_s=period_s, start=start,
                                eval_segments=eval_segments))  # fmt: skip
        except IdentificationError as exc:
            raise IdentificationError(f"delay estimation, candidate nk = {c}: {exc}") from None
    rms = np.array([f.residual_rms for f in fits])
    y_scale = float(np.sqrt(np.mean(np.concatenate([y for y, _ in data]) ** 2)))
    tie = rms.min() + 1e-9 * (rms.min() + y_scale)  # equal up to rounding: the smaller delay wins
    best = int(np.flatnonzero(rms <= tie)[0])
    return DelayEstimate(
        nk=cands[best],
        candidates=cands,
        residual_rms=tuple(float(r) for r in rms),
        fit_prediction_percent=tuple(f.fit_prediction_percent for f in fits),
        fit_simulation_percent=tuple(
            f.fit_simulation_percent if f.model.is_stable() else math.nan for f in fits
        ),
        equations=sum(max(0, len(y) - start) for y, _ in data),
    )


CLOSE_FRACTION = 0.03
"""Candidates whose joint evidence lies within this fraction of the best are too close to call:
another noise realisation of the same experiment can swap them. On the physics simulator's square
experiment (10 V, noise 0.3 rad/s, seeds 1 to 6) nk = 1 and nk = 2 swap places with differences of
up to 2.5 %, while nk = 3 lies 160 % above both."""


@dataclass(frozen=True)
class JointDelay:
    """One input delay for every motor of a cart (they share one loop), and the evidence.

    The joint evidence of a candidate nk (rad/s, smaller is better) is the weighted geometric
    mean of the motors' equation-error RMS, exp(Σ_m w_m ln RMS_m(nk)), w_m = N_m / Σ N with N_m
    motor m's equations: scaling one motor's speeds leaves the ranking alone, so a faster or
    noisier motor does not dominate (up to constants, the log-likelihood of both motors' errors
    with a noise variance of their own). ``close``: the candidates within
    :data:`CLOSE_FRACTION` of the best; ``motors``: each motor's own evidence.
    """

    nk: int
    candidates: tuple[int, ...]
    evidence_rad_s: tuple[float, ...]
    close: tuple[int, ...]
    motors: dict[str, DelayEstimate]

    @property
    def too_close(self) -> bool:
        """Whether more than one candidate is within :data:`CLOSE_FRACTION` of the best."""
        return len(self.close) > 1

    def note(self) -> str | None:
        """One line saying the call was close, which way it went and why; None when it was not."""
        if not self.too_close:
            return None
        best = self.candidates[int(np.argmin(self.evidence_rad_s))]
        shown = ", ".join(
            f"nk = {c}: {self.evidence_rad_s[self.candidates.index(c)]:.4g}" for c in self.close
        )
        why = "the larger: a design for the later answer is the safer one"
        if self.nk == best:
            why += ", and it is also the best"
        return (
            f"--delay auto: too close to call ({shown} rad/s joint evidence, within "
            f"{CLOSE_FRACTION:.0%}); chose nk = {self.nk}, {why}"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "nk": self.nk,
            "evidence": "weighted geometric mean of the motors' equation-error RMS (rad/s)",
            "candidates": [
                {"nk": c, "joint_rms": e}
                for c, e in zip(self.candidates, self.evidence_rad_s, strict=True)
            ],
            "close": list(self.close),
            "too_close": self.too_close,
            "note": self.note(),
            "motors": {
                m: est.nk if est.nk_alone is None else est.nk_alone
                for m, est in self.motors.items()
            },
        }


def joint_delay(estimates: Mapping[str, DelayEstimate]) -> JointDelay:
    """Pick one delay for the motors of ``estimates`` (motor → its :func:`delay_evidence`).

    The smallest joint evidence wins; when others lie within :data:`CLOSE_FRACTION` of it, the
    largest of those close candidates, as a controller designed for the later answer tolerates an
    earlier one better than the reverse. Each estimate comes back with ``nk`` set to the choice.
    """
    if not estimates:
        raise InputError("no delay evidence to choose from")
    first = next(iter(estimates.values()))
    cands = first.candidates
    if any(e.candidates != cands for e in estimates.values()):
        raise InputError("the motors' delay evidence covers different candidates")
    check_distinct(estimates)
    counts = np.array([max(e.equations, 1) for e in estimates.values()], dtype=float)
    weights = counts / counts.sum()
    logs = np.array([np.log(np.maximum(e.residual_rms, 1e-300)) for e in estimates.values()])
    evidence = np.exp(weights @ logs)
    best = float(evidence.min())
    close = tuple(c for c, e in zip(cands, evidence, strict=True)
                  if e <= (1.0 + CLOSE_FRACTION) * best)  # fmt: skip
    nk = max(close)
    motors = {
        m: replace(e, nk=nk, nk_alone=None if e.nk == nk else e.nk) for m, e in estimates.items()
    }
    return JointDelay(nk, cands, tuple(float(v) for v in evidence), close, motors)
