"""Order and delay selection (``--orders``): ARX fits over a grid of (na, nb, nk), compared by

    V = (1/N) Σ ε(k)²,    FPE = V (1 + d/N) / (1 − d/N),    AIC = N ln V + 2d

(ε the equation error in rad/s, d = na + nb; smaller is better) and by the NRMSE fit (%) of the
model simulated from rest on the validation data, or else the raw estimation data (where it
rewards extra parameters). Every fit starts at the grid's largest first row, so all losses are
over the same N equations and compare.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from cartctl.errors import InputError
from cartctl.identification.arx import (
    IdentificationError,
    Segment,
    check_orders,
    first_row,
    fit_arx,
    simulation_fit,
)
from cartctl.measures.metrics import finite_or_none

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
    for part in spec.split(","):
        key, sep, value = (s.strip() for s in part.partition("="))
        if not sep or key not in grid:
            raise InputError(f"--orders: cannot read '{part.strip()}'; {expected}")
        match = re.fullmatch(r"(\d+)(?::(\d+))?", value)
        if match is None:
            raise InputError(
                f"--orders: {key}={value} is not a whole number or a range; {expected}"
            )
        lo = int(match.group(1))
        hi = int(match.group(2)) if match.group(2) is not None else lo
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

    def fit_text(self) -> str:
        if not self.stable:
            return "unstable model"
        return f"{self.fit_percent:.2f}" if math.isfinite(self.fit_percent) else "diverges"


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
        common = {"n_equations": self.n_equations, "fit_on": self.fit_on}
        return [
            r.to_dict()
            | common
            | {"best_aic": "AIC" in self.marks(r), "best_fit": "fit" in self.marks(r)}
            for r in self.rows
        ]

    def format(self) -> str:
        """The terminal table, the best rows marked."""
        fit_head = f"sim fit, {self.fit_on} (%)"
        head = (
            f"    {'na':>3}{'nb':>4}{'nk':>4}{'params':>8}{'loss V (rad/s)²':>17}"
            f"{'AIC (–)':>11}{'FPE (rad/s)²':>14}{fit_head:>26}  best"
        )
        lines = [head]
        for r in self.rows:
            if r.error is not None:
                lines.append(f"    {r.na:>3}{r.nb:>4}{r.nk:>4}{r.params:>8}  not fitted: {r.error}")
                continue
            lines.append(
                f"    {r.na:>3}{r.nb:>4}{r.nk:>4}{r.params:>8}{r.loss:>17.4f}{r.aic:>11.1f}"
                f"{r.fpe:>14.4f}{r.fit_text():>26}  {', '.join(self.marks(r))}".rstrip()
            )
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
    rows = []
    n_eq = 0
    for na, nb, nk in combos:
        d = na + nb
        try:
            fit = fit_arx(segments, na=na, nb=nb, nk=nk, period_s=period_s, start=start,
                          eval_segments=eval_segments)  # fmt: skip
        except IdentificationError as err:
            nan = float("nan")
            rows.append(OrderRow(na, nb, nk, d, nan, nan, nan, nan, False, str(err)))
            continue
        n = fit.n_samples
        n_eq = n
        v = fit.residual_rms**2
        fit_pct = (
            simulation_fit(fit.model, validation) if validation else fit.fit_simulation_percent
        )
        with np.errstate(divide="ignore"):
            aic = n * float(np.log(v)) + 2.0 * d if v > 0.0 else -math.inf
        fpe = v * (1.0 + d / n) / (1.0 - d / n)
        rows.append(OrderRow(na, nb, nk, d, v, aic, fpe, fit_pct, fit.model.is_stable()))
    return OrderTable(tuple(rows), n_eq, "validation" if validation else "estimation")
