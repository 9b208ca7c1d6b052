"""Identification speed: cartctl's ARX fit against bare least-squares solvers, in the same process.

Run: ``python benchmarks/bench_identify.py [--repeats N]``. For 10⁴, 10⁵ and 10⁶ samples of the
report's square-wave experiment on the ground model (with measurement noise) it prints the best of
several runs of

- ``fit_arx``: validation, regressor, one QR of [Φ | y], θ, its standard deviations, the
  prediction fit and the simulation fit (an lfilter over the data);
- the issue's baseline: the regressor built by fancy indexing and ``numpy.linalg.lstsq``;
- ``numpy.linalg.lstsq`` alone, on the same regressor already built;
- a bare ``scipy.linalg.qr`` solve (economic Q and R, θ = R⁻¹ Qᵀy) on the same regressor,

each with its ratio to ``fit_arx``, and the largest θ difference from lstsq. The candidates take
turns in rounds (see :func:`best_of`), so background load falls on all of them alike. A breakdown of ``fit_arx``
at the largest size follows, then the goals of issue 14 (10⁶ samples in at most 0.1 s, at most
1.3× a bare lstsq), met or missed by how much.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import qr, solve_triangular

from cartctl.identification import arx
from cartctl.measures.metrics import sum_squares
from cartctl.model import ArxModel
from cartctl.signals import square

MODEL = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751])
GOAL_SECONDS = 0.1
GOAL_RATIO = 1.3
SETTLE_S = 0.2
"""Pause (s) before each function's runs, for the other BLAS library's threads to go idle."""


def best_of(
    fns: dict[str, Callable[[], object]], repeats: int, rounds: int = 3
) -> dict[str, float]:
    """Best wall time (s) of each function over ``rounds`` rounds of ``repeats`` runs.

    Each round runs every function ``repeats`` times in a row, so background load falls on all
    of them alike, after a pause of :data:`SETTLE_S`: numpy and scipy each bring their own
    multithreaded OpenBLAS, whose threads keep spinning for a while after a call and would slow
    the other library's next calls (on 2 cores, several-fold at 10⁵ samples).
    """
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            time.sleep(SETTLE_S)
            for _ in range(repeats):
                t0 = time.perf_counter()
                fn()
                times[name].append(time.perf_counter() - t0)
    return {name: min(ts) for name, ts in times.items()}


def baseline(y: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """The issue's baseline: regressor by fancy indexing, then numpy's lstsq."""
    k = np.arange(3, y.size)
    phi = np.column_stack([-y[k - 1], -y[k - 2], u[k - 2], u[k - 3]])
    return np.linalg.lstsq(phi, y[k], rcond=None)[0]


def qr_solve(phi: NDArray[np.float64], target: NDArray[np.float64]) -> NDArray[np.float64]:
    """Textbook QR least squares: economic Q and R, θ = R⁻¹ Qᵀy."""
    q, r = qr(phi, mode="economic", check_finite=False)
    return solve_triangular(r, q.T @ target, check_finite=False)


def breakdown(y: NDArray[np.float64], u: NDArray[np.float64], repeats: int) -> dict[str, float]:
    """Best times of fit_arx's parts, run as fit_arx runs them (the QR on a fresh [Φ | y])."""
    data = arx.as_segments([(y, u)])
    model = arx.fit_arx(data).model
    phi_y = arx.augmented_regression(data, 2, 2, 2)

    def validate() -> None:  # fit_arx's own checks: finite segments (as_segments), a moving input
        inputs = [v for _, v in arx.as_segments([(y, u)]) if v.size]
        _ = min(float(v.min()) for v in inputs) == max(float(v.max()) for v in inputs)

    def spread() -> float:
        target = phi_y[:, -1]
        return np.sqrt(sum_squares(target - target.mean()))

    parts = best_of(
        {
            "check the data (finite, excited)": validate,
            "build [Φ | y] (one array, in place)": lambda: arx.augmented_regression(data, 2, 2, 2),
            "target spread (prediction fit)": spread,
            "simulation fit (lfilter, norms)": lambda: arx.simulation_fit(model, data),
        },
        repeats,
    )
    solve_times = []
    for _ in range(3 * repeats):  # least_squares destroys its input: time it on a fresh copy
        fresh = arx.augmented_regression(data, 2, 2, 2)
        t0 = time.perf_counter()
        arx.least_squares(fresh)
        solve_times.append(time.perf_counter() - t0)
    parts["QR, θ, residual, std (least_squares)"] = min(solve_times)
    return parts


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="runs per figure (per round, 3 rounds; default 100, 20, 4 by size)",
    )
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    print(
        f"{'samples':>9} {'fit_arx (s)':>12} {'build+lstsq (s)':>16} {'ratio':>6}"
        f" {'lstsq only (s)':>15} {'ratio':>6} {'scipy QR solve (s)':>19} {'ratio':>6}  max |Δθ|"
    )
    for n, default_repeats in ((10_000, 100), (100_000, 20), (1_000_000, 4)):
        repeats = args.repeats or default_repeats
        u = np.resize(square(10.0, cycles=1), n)
        y = MODEL.simulate(u) + rng.normal(0.0, 0.3, n)
        phi, target = (np.ascontiguousarray(a) for a in arx.stacked_regression([(y, u)], 2, 2, 2))
        t = best_of(
            {
                "fit": lambda: arx.fit_arx([(y, u)]),  # noqa: B023
                "base": lambda: baseline(y, u),  # noqa: B023
                "lstsq": lambda: np.linalg.lstsq(phi, target, rcond=None),  # noqa: B023
                "qr": lambda: qr_solve(phi, target),  # noqa: B023
            },
            repeats,
        )
        delta = np.max(np.abs(arx.fit_arx([(y, u)]).model.theta - baseline(y, u)))
        print(
            f"{n:>9} {t['fit']:>12.4f} {t['base']:>16.4f} {t['fit'] / t['base']:>6.2f}"
            f" {t['lstsq']:>15.4f} {t['fit'] / t['lstsq']:>6.2f}"
            f" {t['qr']:>19.4f} {t['fit'] / t['qr']:>6.2f}  {delta:.1e}"
        )
    parts = breakdown(y, u, repeats)
    print(f"\nfit_arx at {n} samples, by part (best of {3 * repeats} runs each):")
    for name, seconds in parts.items():
        print(f"  {name:<38} {seconds:8.4f} s  {seconds / t['fit']:6.1%}")
    print(f"  {'sum of the parts':<38} {sum(parts.values()):8.4f} s  (fit_arx {t['fit']:.4f} s)")
    print(f"\ngoals of issue 14 at {n} samples:")
    verdict = "met" if t["fit"] <= GOAL_SECONDS else f"missed by {t['fit'] - GOAL_SECONDS:.4f} s"
    print(f"  fit_arx ≤ {GOAL_SECONDS} s: {t['fit']:.4f} s, {verdict}")
    for label, key in (("build+lstsq", "base"), ("lstsq alone", "lstsq")):
        ratio = t["fit"] / t[key]
        verdict = "met" if ratio <= GOAL_RATIO else f"missed by {ratio / GOAL_RATIO - 1:.0%}"
        print(f"  fit_arx ≤ {GOAL_RATIO}× {label}: {ratio:.2f}×, {verdict}")


if __name__ == "__main__":
    main()
