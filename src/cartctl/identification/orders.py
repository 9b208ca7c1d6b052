"""Structure selection by ARX fits on common equations (each candidate starts at the largest
first row of all, so every loss is over the same N equations): the input delay (``--delay
auto``, one for both motors, which share one loop) and the order grid (``--orders``), compared by

    V = (1/N) Σ ε(k)²,    FPE = V (1 + d/N) / (1 − d/N),    AIC = N ln V + 2d

(ε the equation error in rad/s, d = na + nb) and by the simulation fit on the validation data, or
else the raw estimation data.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property, partial
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
    simulation_fit,
)
from cartctl.measures.metrics import finite_or_none


@dataclass(frozen=True)
class DelayEstimate:
    """One motor's delay evidence: each candidate's equation-error RMS (rad/s) on the same
    ``equations`` and its fits (%; the simulation fit −inf when unstable). ``nk`` is this motor's
    best or the joint choice, then ``nk_alone`` this motor's own best where it differs."""

    nk: int
    candidates: tuple[int, ...]
    residual_rms: tuple[float, ...]
    fit_prediction_percent: tuple[float, ...]
    fit_simulation_percent: tuple[float, ...]
    equations: int = 0
    nk_alone: int | None = None

    def to_dict(self) -> dict[str, Any]:
        keys = ("nk", "residual_rms", "fit_prediction_percent", "fit_simulation_percent")
        rows = zip(self.candidates, *(getattr(self, k) for k in keys[1:]), strict=True)
        return {
            "nk": self.nk,
            "nk_alone": self.nk if self.nk_alone is None else self.nk_alone,
            "equations": self.equations,
            "candidates": [dict(zip(keys, row, strict=True)) for row in rows],
        }


INDISTINCT_FRACTION = 1e-3
"""Candidates whose equation errors all lie within this fraction of the best are indistinct."""


def delay_evidence(
    segments: Sequence[Segment],
    *,
    na: int = 2,
    nb: int = 2,
    candidates: Sequence[int] = range(1, 7),
    period_s: float = PERIOD_S,
    eval_segments: Sequence[Segment] | None = None,
) -> DelayEstimate:
    """Fit every candidate delay on common equations (simulation fits on ``eval_segments``): the
    evidence, and the best (smallest equation error; ties up to 1e-9 of the output's RMS to the
    smaller delay). Refusing indistinct evidence is :func:`joint_delay`'s."""
    cands = tuple(int(c) for c in candidates)
    if not cands:
        raise InputError("no candidate delays to try")
    for c in cands:
        check_orders(na, nb, c)
    data = as_segments(segments)
    start = max(first_row(na, nb, c) for c in cands)
    fit = partial(fit_arx, data, period_s=period_s, start=start, eval_segments=eval_segments)
    fits = []
    for c in cands:
        try:
            fits.append(fit(na=na, nb=nb, nk=c))
        except IdentificationError as exc:
            raise IdentificationError(f"delay estimation, candidate nk = {c}: {exc}") from None
    rms = np.array([f.residual_rms for f in fits])
    y_scale = float(np.sqrt(np.mean(np.concatenate([y for y, _ in data]) ** 2)))
    tie = rms.min() + 1e-9 * (rms.min() + y_scale)  # equal up to rounding: the smaller delay wins
    best = int(np.flatnonzero(rms <= tie)[0])
    predicted = tuple(f.fit_prediction_percent for f in fits)
    simulated = tuple(f.fit_simulation_percent for f in fits)
    rms_rad_s = tuple(float(r) for r in rms)
    return DelayEstimate(cands[best], cands, rms_rad_s, predicted, simulated, fits[0].n_samples)


CLOSE_FRACTION = 0.03
"""Candidates within this fraction of the best joint evidence are too close to call: on the
physics simulator's square experiment (10 V, noise 0.3 rad/s, seeds 1 to 6) nk = 1 and 2 swap
places by up to 2.5 % between noise realisations, while nk = 3 lies 160 % above both."""


@dataclass(frozen=True)
class JointDelay:
    """One input delay for the motors of a cart, and the evidence.

    A candidate's joint evidence (rad/s) is the weighted geometric mean of the motors'
    equation-error RMS, exp(Σ_m w_m ln RMS_m(nk)) with w_m = N_m / Σ N (N_m: motor m's
    equations), so scaling one motor's speeds leaves the ranking alone. ``close``: the candidates
    within :data:`CLOSE_FRACTION` of the best; ``motors``: each motor's own evidence.
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
        pairs = zip(self.candidates, self.evidence_rad_s, strict=True)
        own = {m: e.nk if e.nk_alone is None else e.nk_alone for m, e in self.motors.items()}
        return {
            "nk": self.nk,
            "evidence": "weighted geometric mean of the motors' equation-error RMS (rad/s)",
            "candidates": [{"nk": c, "joint_rms": e} for c, e in pairs],
            "close": list(self.close),
            "too_close": self.too_close,
            "note": self.note(),
            "motors": own,
        }


def joint_delay(estimates: Mapping[str, DelayEstimate]) -> JointDelay:
    """One delay for the motors of ``estimates``: the smallest joint evidence or, when others lie
    within :data:`CLOSE_FRACTION` of it, the largest of those (a design for the later answer
    tolerates an earlier one better). Each estimate comes back with ``nk`` the choice. Refuses
    evidence in which no motor tells the candidates apart (:data:`INDISTINCT_FRACTION`)."""
    if not estimates:
        raise InputError("no delay evidence to choose from")
    cands = next(iter(estimates.values())).candidates
    if any(e.candidates != cands for e in estimates.values()):
        raise InputError("the motors' delay evidence covers different candidates")
    rms = [np.asarray(e.residual_rms) for e in estimates.values()]
    if all(r.size >= 2 and r.max() <= (1.0 + INDISTINCT_FRACTION) * r.min() for r in rms):
        raise IdentificationError(
            f"--delay auto cannot tell: the equation errors of nk = "
            f"{', '.join(map(str, cands))} are within {INDISTINCT_FRACTION:.1%} of each other "
            f"({min(r.min() for r in rms):.4g} rad/s); the data does not show when the motor "
            "answers, so give --delay N (2 on board, loop delay + 1 over serial)"
        )
    counts = np.array([max(e.equations, 1) for e in estimates.values()], dtype=float)
    weights = counts / counts.sum()
    logs = np.array([np.log(np.maximum(e.residual_rms, 1e-300)) for e in estimates.values()])
    evidence = np.exp(weights @ logs)
    best = float(evidence.min())
    close = tuple(
        c for c, e in zip(cands, evidence, strict=True) if e <= (1.0 + CLOSE_FRACTION) * best
    )
    nk = max(close)
    motors = {
        m: replace(e, nk=nk, nk_alone=None if e.nk == nk else e.nk) for m, e in estimates.items()
    }
    return JointDelay(nk, cands, tuple(float(v) for v in evidence), close, motors)


DEFAULT_GRID = {"na": (1, 2, 3), "nb": (1, 2, 3), "nk": (1, 2, 3, 4)}
"""The grid of ``--orders`` without a spec: 36 combinations."""

MAX_COMBINATIONS = 400
"""More combinations than this are refused (a grid that large is a typing error)."""

MAX_ORDER_WORK = 40_000
"""The most Σ (na + nb)² over the combinations of ``--orders``: a fit costs about N (na + nb)²,
measured 1e-4 s per unit on a minute of data, so about 5 s a motor per minute (the default grid
is 624; na = nb = 50 alone is 10 000)."""

_LOW = {"na": 0, "nb": 1, "nk": 0}


def parse_grid(spec: str | None) -> dict[str, tuple[int, ...]]:
    """Parse ``na=1:3,nb=1:3,nk=1:4`` (each a whole number or an inclusive range); keys left out
    keep :data:`DEFAULT_GRID`'s values, as does an empty spec or None."""
    grid = dict(DEFAULT_GRID)
    if spec is None or not spec.strip():
        return grid
    expected = (
        "expected e.g. na=1:3,nb=1:3,nk=1:4 (each a whole number or an inclusive range lo:hi)"
    )
    seen: set[str] = set()
    for part in spec.split(","):
        key, sep, value = (s.strip() for s in part.partition("="))
        if not sep or key not in grid:
            raise InputError(f"--orders: cannot read '{part.strip()}'; {expected}")
        if key in seen:
            raise InputError(f"--orders: {key} is given twice; give each of na, nb, nk once")
        seen.add(key)
        match = re.fullmatch(r"(\d+)(?::(\d+))?", value)
        if match is None:
            raise InputError(
                f"--orders: {key}={value} is not a whole number or a range; {expected}"
            )
        lo, hi = int(match[1]), int(match[2] or match[1])
        if hi < lo or lo < _LOW[key] or hi > 50:
            raise InputError(
                f"--orders: {key}={value} must be a range lo:hi with {_LOW[key]} <= lo <= hi <= 50"
            )
        grid[key] = tuple(range(lo, hi + 1))
    count = math.prod(len(v) for v in grid.values())
    if count > MAX_COMBINATIONS:
        raise InputError(
            f"--orders: {count} combinations is too many (at most {MAX_COMBINATIONS}); narrow the ranges"
        )
    work = len(grid["nk"]) * sum((na + nb) ** 2 for na in grid["na"] for nb in grid["nb"])
    if work > MAX_ORDER_WORK:
        raise InputError(
            f"--orders: the fits of this grid cost {work} (the sum of (na + nb)² over its "
            f"{count} combinations), more than {MAX_ORDER_WORK}; narrow the ranges or lower the "
            "orders"
        )
    return grid


@dataclass(frozen=True)
class OrderRow:
    """One combination's loss V ((rad/s)²), AIC, FPE ((rad/s)²) and simulation fit (%, −inf when
    unstable); NaN with ``error`` saying why it could not be fitted."""

    na: int
    nb: int
    nk: int
    params: int
    loss: float
    aic: float
    fpe: float
    fit_percent: float
    stable: bool
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        return out | {k: finite_or_none(out[k]) for k in ("loss", "aic", "fpe", "fit_percent")}


@dataclass(frozen=True)
class OrderTable:
    """All combinations, the common number of equations N, and the data the fit is on
    ('validation' or 'estimation')."""

    rows: tuple[OrderRow, ...]
    n_equations: int
    fit_on: str

    @cached_property
    def _best(self) -> tuple[OrderRow | None, OrderRow | None]:
        """The row of smallest AIC and that of largest fit of a stable model."""
        aic = [r for r in self.rows if math.isfinite(r.aic)]
        fit = [r for r in self.rows if r.stable and math.isfinite(r.fit_percent)]
        return (
            min(aic, key=lambda r: (r.aic, r.params)) if aic else None,
            max(fit, key=lambda r: (r.fit_percent, -r.params)) if fit else None,
        )

    def marks(self, row: OrderRow) -> list[str]:
        """'AIC' and/or 'fit' when ``row`` is the best by that criterion."""
        return [m for m, b in zip(("AIC", "fit"), self._best, strict=True) if row is b]

    def to_dict(self) -> list[dict[str, Any]]:
        """The ``orders`` list of ``identify --json``: one entry per row, the best ones marked."""
        aic, fit = self._best
        common = {"n_equations": self.n_equations, "fit_on": self.fit_on}
        return [
            r.to_dict() | common | {"best_aic": r is aic, "best_fit": r is fit} for r in self.rows
        ]

    def cells(self, r: OrderRow) -> list[str]:
        """Loss, AIC, FPE and fit as printed; for a row not fitted, empty numbers and the error."""
        if r.error is not None:
            return ["", "", "", r.error]
        fit = f"{r.fit_percent:.2f}" if math.isfinite(r.fit_percent) else "diverges"
        fit = fit if r.stable else "unstable model"
        return [f"{r.loss:.4f}", f"{r.aic:.1f}", f"{r.fpe:.4f}", fit]

    def format(self) -> str:
        """The terminal table, the best rows marked."""
        fit_head = f"sim fit, {self.fit_on} (%)"
        lines = [
            f"    {'na':>3}{'nb':>4}{'nk':>4}{'params':>8}{'loss V (rad/s)²':>17}"
            f"{'AIC (–)':>11}{'FPE (rad/s)²':>14}{fit_head:>26}  best"
        ]
        for r in self.rows:
            head = f"    {r.na:>3}{r.nb:>4}{r.nk:>4}{r.params:>8}"
            if r.error is not None:
                lines.append(f"{head}  not fitted: {r.error}")
                continue
            loss, aic, fpe, fit = self.cells(r)
            marks = ", ".join(self.marks(r))
            lines.append(f"{head}{loss:>17}{aic:>11}{fpe:>14}{fit:>26}  {marks}".rstrip())
        lines.append(
            f"    N = {self.n_equations} equations for every row; V = mean squared equation error, "
            "AIC = N ln V + 2d, FPE = V (1 + d/N) / (1 − d/N), d = na + nb; sim fit: NRMSE of the "
            f"simulation on the {self.fit_on} data; best: smallest AIC, largest fit of a stable model"
        )
        return "\n".join(lines)


def order_table(
    segments: Sequence[Segment],
    grid: dict[str, tuple[int, ...]],
    *,
    period_s: float,
    eval_segments: Sequence[Segment],
    validation: Sequence[Segment] | None = None,
) -> OrderTable:
    """Fit ARX for every (na, nb, nk) of ``grid`` on common equations of ``segments`` (rad/s, V;
    prefiltered, if asked). The fit is on ``validation``, else on ``eval_segments`` (raw data)."""
    combos = list(itertools.product(grid["na"], grid["nb"], grid["nk"]))
    for na, nb, nk in combos:
        check_orders(na, nb, nk)
    start = max(first_row(na, nb, nk) for na, nb, nk in combos)
    arx = partial(fit_arx, segments, period_s=period_s, start=start, eval_segments=eval_segments)
    rows = []
    n_eq = 0
    for na, nb, nk in combos:
        d = na + nb
        try:
            fit = arx(na=na, nb=nb, nk=nk)
        except IdentificationError as err:
            nan = float("nan")
            rows.append(OrderRow(na, nb, nk, d, nan, nan, nan, nan, False, str(err)))
            continue
        n_eq = n = fit.n_samples
        v = fit.residual_rms**2
        pct = simulation_fit(fit.model, validation) if validation else fit.fit_simulation_percent
        aic = n * float(np.log(v)) + 2.0 * d if v > 0.0 else -math.inf
        fpe = v * (1.0 + d / n) / (1.0 - d / n)
        rows.append(OrderRow(na, nb, nk, d, v, aic, fpe, pct, fit.model.is_stable()))
    return OrderTable(tuple(rows), n_eq, "validation" if validation else "estimation")
