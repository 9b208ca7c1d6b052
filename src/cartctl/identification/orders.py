"""Order and delay selection: ARX fits over a grid of (na, nb, nk) with AIC, FPE and a fit.

Every combination is fitted by least squares on the same equations: the first row is the largest
first row of the grid, max over the grid of max(na, nk + nb − 1), so every fit's loss is over the
same N samples and the criteria compare. With d = na + nb parameters and the loss

    V = (1/N) Σ ε(k)²          (equation error, (rad/s)²)

the criteria are Akaike's

    FPE = V (1 + d/N) / (1 − d/N)          ((rad/s)²)
    AIC = N ln V + 2d

(smaller is better; both penalise parameters that only fit the noise). The fit is the NRMSE fit
(%) of the model simulated from rest on the validation data when there is any, else on the raw
estimation data (where it rewards extra parameters).
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
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

__all__ = ["DEFAULT_GRID", "OrderRow", "OrderTable", "order_table", "parse_grid"]

DEFAULT_GRID = {"na": (1, 2, 3), "nb": (1, 2, 3), "nk": (1, 2, 3, 4)}
"""The grid of ``--orders`` without a spec: 36 combinations."""

MAX_COMBINATIONS = 400
"""More combinations than this are refused (a grid that large is a typing error)."""

MAX_ORDER_WORK = 40_000
"""The most Σ (na + nb)² over the combinations of ``--orders``. A combination's fit and
simulation cost about N·(na + nb)²: measured, 1e-4 s per unit of the sum for a motor on a minute
of data (N = 6000), so this is about 5 s a motor per minute of data (the default grid is 624;
na = nb = 50 alone is 10 000)."""

_LOW = {"na": 0, "nb": 1, "nk": 0}


def parse_grid(spec: str | None) -> dict[str, tuple[int, ...]]:
    """Parse ``na=1:3,nb=1:3,nk=1:4``: each key a whole number or an inclusive range lo:hi.

    Keys left out keep :data:`DEFAULT_GRID`'s values; an empty spec or None is the default grid.

    Raises
    ------
    InputError
        An unknown key, a malformed value, a range outside the allowed values, or more than
        :data:`MAX_COMBINATIONS` combinations.
    """
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
    """One combination's fit and criteria (``loss`` etc. are NaN when the fit failed).

    Attributes
    ----------
    na, nb, nk : int
    params : int
        d = na + nb.
    loss : float
        V, mean squared equation error ((rad/s)²).
    aic : float
    fpe : float
        (rad/s)².
    fit_percent : float
        Simulation fit (%) on the validation data (or estimation data); −inf when unstable.
    stable : bool
    error : str or None
        Why the combination could not be fitted (rank deficient, too few samples).
    """

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
        return {
            "na": self.na,
            "nb": self.nb,
            "nk": self.nk,
            "params": self.params,
            "loss": finite_or_none(self.loss),
            "aic": finite_or_none(self.aic),
            "fpe": finite_or_none(self.fpe),
            "fit_percent": finite_or_none(self.fit_percent),
            "stable": self.stable,
            "error": self.error,
        }


@dataclass(frozen=True)
class OrderTable:
    """All combinations, the common number of equations, and which data the fit is on.

    Attributes
    ----------
    rows : tuple of OrderRow
    n_equations : int
        N, the same for every row.
    fit_on : {'validation', 'estimation'}
    """

    rows: tuple[OrderRow, ...]
    n_equations: int
    fit_on: str

    def best_aic(self) -> OrderRow | None:
        ok = [r for r in self.rows if math.isfinite(r.aic)]
        return min(ok, key=lambda r: (r.aic, r.params)) if ok else None

    def best_fit(self) -> OrderRow | None:
        ok = [r for r in self.rows if r.stable and math.isfinite(r.fit_percent)]
        return max(ok, key=lambda r: (r.fit_percent, -r.params)) if ok else None

    def to_dict(self) -> list[dict[str, Any]]:
        """The ``orders`` list of ``identify --json``: one entry per row, the best ones marked."""
        best_aic, best_fit = self.best_aic(), self.best_fit()
        return [
            row.to_dict()
            | {
                "n_equations": self.n_equations,
                "fit_on": self.fit_on,
                "best_aic": row is best_aic,
                "best_fit": row is best_fit,
            }
            for row in self.rows
        ]

    def format(self) -> str:
        """The terminal table, the best rows marked."""
        best_aic, best_fit = self.best_aic(), self.best_fit()
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
            fit = f"{r.fit_percent:.2f}" if math.isfinite(r.fit_percent) else "diverges"
            if not r.stable:
                fit = "unstable model"
            marks = [m for m, b in (("AIC", best_aic), ("fit", best_fit)) if r is b]
            lines.append(
                f"    {r.na:>3}{r.nb:>4}{r.nk:>4}{r.params:>8}{r.loss:>17.4f}{r.aic:>11.1f}"
                f"{r.fpe:>14.4f}{fit:>26}  {', '.join(marks)}".rstrip()
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
    """Fit ARX for every (na, nb, nk) of the grid on common equations (see the module docstring).

    Parameters
    ----------
    segments : sequence of (y, u)
        Estimation experiments (rad/s, V), prefiltered if asked for.
    grid : dict
        ``na``, ``nb``, ``nk`` → values (:func:`parse_grid`).
    period_s : float
        Sample period (s).
    eval_segments : sequence of (y, u)
        Raw estimation data, for the fit when there is no validation data.
    validation : sequence of (y, u), optional
        Validation data for the fit.

    Returns
    -------
    OrderTable
    """
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
