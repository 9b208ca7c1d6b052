"""Input-delay estimation: which nk makes the ARX structure explain the data best.

The report assumes nk = 2 (one sample from the zero-order hold, one from microOS). A PC-side loop
over serial adds ticks. Here every candidate delay is fitted on the same equations (a common first
row), and the one with the smallest equation-error loss wins; the table of losses and fits is the
evidence, reported to the user.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

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
        The chosen input delay (samples).
    candidates : tuple of int
        Delays tried.
    residual_rms : tuple of float
        Equation-error RMS (rad/s) of each candidate's ARX fit, on common equations.
    fit_prediction_percent, fit_simulation_percent : tuple of float
        Each candidate's fits (%); the simulation fit is NaN (null in JSON) for a candidate whose
        model is unstable, as its simulation runs away and the figure would mean nothing.
    """

    nk: int
    candidates: tuple[int, ...]
    residual_rms: tuple[float, ...]
    fit_prediction_percent: tuple[float, ...]
    fit_simulation_percent: tuple[float, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the choice and one row per candidate."""
        return {
            "nk": self.nk,
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


def estimate_delay(
    segments: Sequence[Segment],
    *,
    na: int = 2,
    nb: int = 2,
    candidates: Sequence[int] = range(1, 7),
    period_s: float = 0.01,
    eval_segments: Sequence[Segment] | None = None,
) -> DelayEstimate:
    """Pick the input delay with the smallest ARX equation error.

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
        Ties (equal losses up to rounding, 1e-9 of the output's RMS) go to the smaller delay.

    Raises
    ------
    IdentificationError
        Every candidate's loss within :data:`INDISTINCT_FRACTION` of the best: the data cannot
        tell the delays apart.
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
    if len(cands) > 1 and rms.max() <= (1.0 + INDISTINCT_FRACTION) * rms.min():
        raise IdentificationError(
            f"--delay auto cannot tell: the equation errors of nk = "
            f"{', '.join(map(str, cands))} are within {INDISTINCT_FRACTION:.1%} of each other "
            f"({rms.min():.4g} rad/s); the data does not show when the motor answers, so give "
            "--delay N (2 on board, loop delay + 1 over serial)"
        )
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
    )
