"""What ``cartctl run --fast`` spends per tick: the loop alone, then with each sink, then all of them.

Run: ``python benchmarks/fast_parts.py [--seconds 120]`` from the repository root, or through
``bench_run.py``. For both shipped controllers on both simulators it builds the loop as
``cartctl run --fast`` does (the shipped controller file, the plant, the CSV sink in blocks of
1000 rows, the memory sink, the Rerun sink saving blocks of 1000 ticks to a file, the
:class:`~cartctl.runtime.executor.BackToBackExecutor`, the collector paused) and times, in this
process and one after the other:

- ``no sink``: the loop alone (plant, estimators, controllers, the row);
- ``+ csv``, ``+ memory``, ``+ rerun``: the loop with that one sink;
- ``all sinks``: what ``run --fast`` runs (less its start-up and summary).

The time runs from the first tick until the loop has finished, its files complete: the Rerun sink
sends one entity's column per ``idle`` call, so on the fast loop most of its sending is left for
``finish`` and belongs in the figure.

Each figure is the best of three runs of ``--seconds`` simulated seconds, in µs per tick and as a
speed-up over real time (10 ms per tick), beside the goal of 2000× (5 µs per tick).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.plants.factory import make_plant
from cartctl.reference import reference_signal
from cartctl.runtime.executor import BackToBackExecutor, SimulatedClock
from cartctl.runtime.loop import ControlLoop, MemorySink
from cartctl.runtime.realtime import gc_paused
from cartctl.sinks.csv_sink import CsvSink
from cartctl.sinks.rerun_sink import RerunSink

VARIANTS = ("no sink", "+ csv", "+ memory", "+ rerun", "all sinks")


def _sinks(variant: str, out: Path) -> list[Any]:
    make = {
        "csv": lambda: CsvSink(out / "t.csv", flush_every=1000),
        "memory": MemorySink,
        "rerun": lambda: RerunSink("save", out / "t.rrd", batch_ticks=1000),
    }
    if variant == "all sinks":
        return [f() for f in make.values()]
    if variant.startswith("+ "):
        return [make[variant[2:]]()]
    return []


def us_per_tick(plant_spec: str, controller_path: str, variant: str, seconds: float) -> float:
    """One fast run of the loop with the variant's sinks; wall time per tick (µs)."""
    controller = load_controller(controller_path)
    plant, _ = make_plant(plant_spec)
    n = round(seconds / plant.period_s)
    ref = reference_signal("square:8:2", n, plant.period_s)
    with tempfile.TemporaryDirectory() as out:
        clock = SimulatedClock()
        loop = ControlLoop(plant, build_controllers(controller), {"a": ref, "b": ref},
                           _sinks(variant, Path(out)), now_s=clock.now_s,
                           voltage_limit_v=controller.voltage_limit_v, period_s=plant.period_s)  # fmt: skip
        executor = BackToBackExecutor(plant.period_s, max_ticks=n)
        tick = loop.tick
        period_s = plant.period_s
        finished = False
        try:
            with gc_paused():
                loop.start()
                t0 = time.perf_counter()
                executor.run(lambda k: tick(k, 0.0, 0.0, k * period_s), loop.idle)
                loop.finish()  # the files complete: what the sinks left for the end is paid here
                elapsed = time.perf_counter() - t0
                finished = True
        finally:
            if not finished:
                loop.finish()
    return elapsed / n * 1e6


def report(seconds: float) -> None:
    """Print the table for both shipped controllers on both simulators."""
    print(f"  {'controller':<12}{'plant':<9}" + "".join(f"{v:>16}" for v in VARIANTS))
    for controller in ("pi", "poles"):
        for plant in ("sim", "physics"):
            cells = []
            for variant in VARIANTS:
                path = f"controllers/{controller}.toml"
                us = min(us_per_tick(plant, path, variant, seconds) for _ in range(3))
                cells.append(f"{us:6.2f} µs {1e4 / us:5.0f}×")
            print(f"  {controller + '.toml':<12}{plant:<9}" + "".join(f"{c:>16}" for c in cells))
    print("  (goal: 2000× real time, 5 µs per tick, with every sink)")


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--seconds", type=float, default=120.0, help="simulated seconds per run (default 120)"
    )
    report(parser.parse_args().seconds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
