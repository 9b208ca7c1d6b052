"""Identification speed: cartctl's ARX fit against a plain numpy lstsq, in the same process.

Run: ``python benchmarks/bench_identify.py``. For 10⁴, 10⁵ and 10⁶ samples of the report's
square-wave experiment on the ground model (with measurement noise) it prints the best of several
runs of ``fit_arx`` (QR solve, θ standard deviations, simulation and prediction fits) and of a
bare ``numpy.linalg.lstsq`` on the same regression, with their ratio. The goal: 10⁶ samples in
well under a second.
"""

from __future__ import annotations

import time

import numpy as np

from cartctl.identification.arx import fit_arx
from cartctl.model import ArxModel
from cartctl.signals import square

MODEL = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751])


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def baseline(y: np.ndarray, u: np.ndarray) -> np.ndarray:
    k = np.arange(3, y.size)
    phi = np.column_stack([-y[k - 1], -y[k - 2], u[k - 2], u[k - 3]])
    return np.linalg.lstsq(phi, y[k], rcond=None)[0]


def main() -> None:
    rng = np.random.default_rng(0)
    print(f"{'samples':>9} {'fit_arx (s)':>12} {'numpy lstsq (s)':>16} {'ratio':>7}  max |Δθ|")
    for n in (10_000, 100_000, 1_000_000):
        u = np.resize(square(10.0, cycles=1), n)
        y = MODEL.simulate(u) + rng.normal(0.0, 0.3, n)
        repeats = 5 if n < 1_000_000 else 3
        t_fit = best_of(lambda: fit_arx([(y, u)]), repeats)  # noqa: B023
        t_base = best_of(lambda: baseline(y, u), repeats)  # noqa: B023
        delta = np.max(np.abs(fit_arx([(y, u)]).model.theta - baseline(y, u)))
        print(f"{n:>9} {t_fit:>12.4f} {t_base:>16.4f} {t_fit / t_base:>7.2f}  {delta:.1e}")


if __name__ == "__main__":
    main()
