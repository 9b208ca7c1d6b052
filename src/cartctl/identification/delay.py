"""Input-delay estimation: which nk makes the ARX structure explain the data best.

The report assumes nk = 2 (one sample from the zero-order hold, one from microOS). A PC-side loop
over serial adds ticks. Here every candidate delay is fitted on the same equations (a common first
row), and the one with the smallest equation-error loss wins; the table of losses and fits is the
evidence, reported to the user. Both motors of a cart share one loop, so :func:`joint_delay` picks
one delay for both from their joint evidence, and says when the best candidates are too close to
call.
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
    """The chosen delay and the evidence for it.

    Attributes
    ----------
    nk : int
        The chosen input delay (samples): this motor's best, or the one chosen for both motors
        (:func:`joint_delay`).
    candidates : tuple of int
        Delays tried.
    residual_rms : tuple of float
        Equation-error RMS (rad/s) of each candidate's ARX fit, on common equations.
    fit_prediction_percent, fit_simulation_percent : tuple of float
        Each candidate's fits (%); the simulation fit is NaN (null in JSON) for a candidate whose
        model is unstable, as its simulation runs away and the figure would mean nothing.
    equations : int
        Number of equations each candidate's loss is computed on (the same for all).
    nk_alone : int or None
        This motor's own best delay when ``nk`` was chosen jointly with the other motor and
        differs from it; None otherwise.
    """

    nk: int
    candidates: tuple[int, ...]
    residual_rms: tuple[float, ...]
    fit_prediction_percent: tuple[float, ...]
    fit_simulation_percent: tuple[float, ...]
    equations: int = 0
    nk_alone: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the choice and one row per candidate."""
        return {
            "nk": self.nk,
            "nk_alone": self.nk if self.nk_alone is None else self.nk_alone,
            "equations": self.equations,
            "candidates": [
                {
                    "nk": nk,
                    "residual_rms": r,
                    "fit_prediction_percent": p,
                    "fit_simulation_percent": s,
                }
                for nk, r, p, s in zip(
                    self.candidates,
                    self.residual_rms,
                    self.fit_prediction_percent,
                    self.fit_simulation_percent,
                    strict=True,
                )
            ],
        }


INDISTINCT_FRACTION = 1e-3
"""Candidates whose equation errors all lie within this fraction of the best cannot be told apart."""


def check_distinct(estimates: Mapping[str, DelayEstimate]) -> None:
    """Refuse evidence that cannot tell the delays apart: every candidate's equation error
    within :data:`INDISTINCT_FRACTION` of the best, for every motor of ``estimates``.

    Raises
    ------
    IdentificationError
        The data does not show when the motor answers.
    """
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
    """Fit every candidate delay on common equations: the evidence, and this motor's best.

    Nothing is refused for being too close (:func:`check_distinct` does that).

    Parameters
    ----------
    segments : sequence of (y, u)
        Experiments (rad/s, V).
    na, nb : int
        Model orders.
    candidates : sequence of int
        Delays to try (samples), default 1..6.
    period_s : float
        Sample period (s).
    eval_segments : sequence of (y, u), optional
        Raw data for the simulation fits (when ``segments`` is prefiltered).

    Returns
    -------
    DelayEstimate
        The best delay has the smallest ARX equation error; ties (equal losses up to rounding,
        1e-9 of the output's RMS) go to the smaller delay.
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
            fits.append(
                fit_arx(
                    data,
                    na=na,
                    nb=nb,
                    nk=c,
                    period_s=period_s,
                    start=start,
                    eval_segments=eval_segments,
                )
            )
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

    The joint evidence of a candidate nk is the weighted geometric mean of the motors'
    equation-error RMS, exp(Σ_m w_m ln RMS_m(nk)) with w_m = N_m / Σ N (N_m: motor m's number of
    equations). It is normalised per motor: scaling one motor's speeds scales its RMS by the same
    factor for every candidate and leaves the ranking alone, so a faster or noisier motor does
    not dominate. Its logarithm is, up to constants, the Gaussian log-likelihood of both motors'
    equation errors with a noise variance of their own.

    Attributes
    ----------
    nk : int
        The chosen delay (samples).
    candidates : tuple of int
    evidence_rad_s : tuple of float
        The joint evidence of each candidate (rad/s; smaller is better).
    close : tuple of int
        The candidates within :data:`CLOSE_FRACTION` of the best (the best included).
    motors : dict of str to DelayEstimate
        Each motor's own evidence.
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
        """JSON form (``identify --json``'s ``"delay"``)."""
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

    The candidate with the smallest joint evidence (see :class:`JointDelay`) wins; when others
    lie within :data:`CLOSE_FRACTION` of it, the larger of those close candidates is chosen, since
    a controller designed for the later answer tolerates an earlier one better than the reverse.
    Each motor's estimate comes back with ``nk`` set to the choice (and ``nk_alone`` to its own
    best where that differs).

    Raises
    ------
    InputError
        No estimates, or estimates over different candidates.
    IdentificationError
        No motor's data can tell the candidates apart (:func:`check_distinct`).
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
