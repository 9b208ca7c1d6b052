"""How long ``cartctl tune --robust`` takes on a 10 × 10 grid over 200 plants, against the loop run
once per plant.

For each method (pi, poles), in one process run:

1. the whole command, ``cartctl tune models/ground.toml --method M --grid <10 × 10> --robust
   --plants 200 --jobs J`` (in process, output discarded): wall time;
2. the simulation of the 201 plants (nominal + 200 sampled) of one design, both ways, on one core:
   the vectorised loop (:func:`cartctl.tune.batch.simulate_batch`, both motors, plus its metrics)
   against the per-plant Python loop (``run_in_memory`` with an ``ArxPlant`` and ``trace_metrics``,
   both motors in one run) timed on a few plants and scaled to 201, on a few designs;
3. the baseline for the whole grid: the command's time with its batch part replaced by the
   per-plant loop's, spread over the same J processes.

    python benchmarks/bench_tune.py [--jobs 2] [--plants 200] [--baseline-plants 6]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import time
from pathlib import Path

from cartctl.cart import encoder_quantum_rad_s
from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.design.make import design_motor
from cartctl.plants.sim import ArxPlant
from cartctl.reference import reference_signal
from cartctl.runtime.loop import run_in_memory
from cartctl.sinks.summary import trace_metrics
from cartctl.tune.batch import ArxBatch, sample_plants, simulate_batch
from cartctl.tune.grid import design_request, grid_settings, parse_grid
from cartctl.tune.robust import step_metrics

MODEL = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
GRIDS = {
    "pi": "phase-margin=60:78:2,crossover-hz=3:7.5:0.5",
    "poles": "settling-time=0.04:0.22:0.02,overshoot=0.5:5:0.5",
}
"""10 × 10 grids where every setting is feasible on the ground model (so every one is simulated)."""


def time_command(method: str, plants: int, jobs: int) -> tuple[float, int]:
    """Wall time (s) of the whole ``tune --robust`` command, and its number of settings."""
    argv = ["tune", str(MODEL), "--method", method, "--grid", GRIDS[method], "--robust",
            "--plants", str(plants), "--jobs", str(jobs)]  # fmt: skip
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(argv)
    elapsed = time.perf_counter() - start
    if code != 0:
        raise SystemExit(f"cartctl tune failed with exit code {code}")
    return elapsed, len(grid_settings(parse_grid(GRIDS[method], method)))


def time_simulation(method: str, plants: int, baseline_plants: int) -> tuple[float, float]:
    """Per design, on one core: seconds to simulate nominal + ``plants`` plants (both motors) with
    the batch loop and its metrics, and with the per-plant loop (scaled from
    ``baseline_plants`` plants). The mean over three designs from the grid's corners and middle."""
    models = load_models(MODEL)
    sample = sample_plants(models, plants, seed=1)
    settings = grid_settings(parse_grid(GRIDS[method], method))
    picks = [settings[0], settings[len(settings) // 2], settings[-1]]
    n, ts = 200, models.period_s
    refs = {m: reference_signal("step:10", n, ts, m) for m in ("a", "b")}
    floor = encoder_quantum_rad_s(ts)
    batch_s, loop_s = [], []
    for s in picks:
        request = design_request(method, s)
        ctrls = {m: design_motor(request, models.motor(m)).controller for m in ("a", "b")}
        batches = {}
        for m in ("a", "b"):
            nominal = models.motor(m)
            motor = sample.motors[m]
            batches[m] = ArxBatch.from_arrays([nominal.ar, *motor.ar], [nominal.b, *motor.b],
                                              [nominal.nk, *motor.nk], period_s=ts)  # fmt: skip
        start = time.perf_counter()
        for m in ("a", "b"):
            step_metrics(simulate_batch(ctrls[m], batches[m], refs[m]), floor)
        batch_s.append(time.perf_counter() - start)
        start = time.perf_counter()
        for i in range(baseline_plants):
            plant = ArxPlant(sample.motors["a"].model(i, ts), sample.motors["b"].model(i, ts))
            columns, _ = run_in_memory(plant, ctrls, refs, period_s=ts, voltage_limit_v=12.0)
            trace_metrics(columns, ts)
        loop_s.append((time.perf_counter() - start) / baseline_plants * (plants + 1))
    return sum(batch_s) / len(batch_s), sum(loop_s) / len(loop_s)


def main_bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--plants", type=int, default=200)
    parser.add_argument("--baseline-plants", type=int, default=6)
    args = parser.parse_args()
    print(f"cartctl tune --robust, 10 x 10 grid, {args.plants} plants, 2 s step, "
          f"{args.jobs} process(es), {os.cpu_count()} core(s)")  # fmt: skip
    for method in ("pi", "poles"):
        total_s, designs = time_command(method, args.plants, args.jobs)
        batch_s, loop_s = time_simulation(method, args.plants, args.baseline_plants)
        baseline_s = total_s + designs * (loop_s - batch_s) / args.jobs
        print(f"{method:>5}: tune --robust {total_s:6.1f} s for {designs} designs x "
              f"{args.plants + 1} plants; per design on one core: batch {batch_s * 1e3:6.1f} ms, "
              f"per-plant loop {loop_s * 1e3:7.1f} ms (from {args.baseline_plants} plants, "
              f"x{loop_s / batch_s:.0f}); the grid with the per-plant loop: about {baseline_s:6.1f} s "
              f"(x{baseline_s / total_s:.1f} the command)")  # fmt: skip


if __name__ == "__main__":
    main_bench()
