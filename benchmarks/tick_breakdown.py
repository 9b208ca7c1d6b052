"""Where one tick of ``cartctl run`` spends its time: plant, estimator, controller, each sink, loop.

Run: ``python benchmarks/tick_breakdown.py [--seconds 20] [--plant physics] [--controller
controllers/poles.toml] [--rerun save|off] [--fast] [--busy]``, or through ``bench_run.py``.

It builds the loop as ``cartctl run`` does (the shipped controller file, the plant, the CSV, memory
and Rerun sinks, the periodic executor on the monotonic clock with SCHED_FIFO where permitted, the
collector paused), then wraps each part's per-tick call with a timer:

- ``plant``: ``plant.step`` (both motors);
- ``estimator``: the estimators' ``correct`` and ``predict`` inside the controllers;
- ``controller``: the controllers' ``step`` less their estimators;
- ``sink csv``, ``sink memory``, ``sink rerun``: each sink's ``write``;
- ``loop``: the rest of ``ControlLoop.tick`` (references, clamping, the row, the bookkeeping);
- ``executor``: the tick's compute time outside ``ControlLoop.tick`` (the executor's call, and
  this script's own per-tick bookkeeping of the timers);
- ``tick``: the executor's compute time, the figure ``run --json`` reports;
- ``idle``: the sinks' work after the tick (formatting the CSV, packing and sending the Rerun
  blocks), outside the compute time; counted with the next tick's sample.

Each timer costs about 0.1 µs, so the parts add up to a little more than an untimed tick. The
table gives p50, p99 and max per part (µs), and, for the ticks above the tick's p99, which part
took the most time in them: the answer to "where do the outliers come from". Then each tick that
started more than 1 ms late, with the tick and the idle work before it: whether the process ran
late or woke late. ``--busy`` keeps one other core busy meanwhile (as ``bench_run.py --soak``).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from array import array
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from bench_loop import busy_core
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.plants.factory import make_plant
from cartctl.reference import reference_signal
from cartctl.runtime.executor import MonotonicClock, PeriodicExecutor, SimulatedClock
from cartctl.runtime.loop import ControlLoop, MemorySink
from cartctl.runtime.realtime import enable_realtime, gc_paused, restore
from cartctl.sinks.csv_sink import CsvSink
from cartctl.sinks.rerun_sink import RerunSink

PARTS = ("plant", "estimator", "controller", "sink csv", "sink memory", "sink rerun", "loop",
         "executor", "tick", "idle")  # fmt: skip


class Timers:
    """Per-tick sums of each part's time (s), closed into per-tick samples by :meth:`close_tick`."""

    def __init__(self) -> None:
        self.now: dict[str, float] = dict.fromkeys(PARTS, 0.0)
        self.samples: dict[str, array] = {p: array("d") for p in PARTS}

    def wrap(self, part: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        clock, now = time.perf_counter, self.now

        def timed(*args: Any) -> Any:
            t = clock()
            try:
                return fn(*args)
            finally:
                now[part] += clock() - t

        return timed

    def close_tick(self) -> None:
        for part, value in self.now.items():
            self.samples[part].append(value * 1e6)
            self.now[part] = 0.0


class _TimedController:
    """A controller whose ``step`` is timed (controllers with ``__slots__`` cannot be patched)."""

    def __init__(self, ctrl: Any, step: Callable[[float, float], float]) -> None:
        self._ctrl, self.step = ctrl, step

    def __getattr__(self, name: str) -> Any:
        return getattr(self._ctrl, name)


def instrument(loop: ControlLoop, timers: Timers) -> None:
    """Wrap the plant, the estimators, the controllers and the sinks of ``loop`` with timers."""
    loop.plant.step = timers.wrap("plant", loop.plant.step)  # type: ignore[method-assign]
    for motor, ctrl in loop.controllers.items():
        est = getattr(ctrl, "estimator", None)
        if est is not None:
            est.correct = timers.wrap("estimator", est.correct)
            est.predict = timers.wrap("estimator", est.predict)
        loop.controllers[motor] = _TimedController(ctrl, timers.wrap("controller", ctrl.step))
    names = {CsvSink: "sink csv", MemorySink: "sink memory", RerunSink: "sink rerun"}
    for sink in loop.sinks:
        sink.write = timers.wrap(names[type(sink)], sink.write)  # type: ignore[method-assign]


def measure(
    seconds: float, plant_spec: str, controller_path: str, rerun: str, fast: bool
) -> dict[str, np.ndarray]:
    """Run the instrumented loop; per-tick samples (µs) of each part."""
    controller = load_controller(controller_path)
    controllers = build_controllers(controller)
    plant, _ = make_plant(plant_spec)
    n = round(seconds / plant.period_s)
    ref = reference_signal("square:8:2", n, plant.period_s)
    timers = Timers()
    with tempfile.TemporaryDirectory() as out:
        sinks: list[Any] = [
            CsvSink(Path(out) / "t.csv", flush_every=1000 if fast else 50),
            MemorySink(),
        ]
        if rerun != "off":
            # as cartctl run makes it: blocks of 20 ticks live, 1000 on the simulated clock
            sinks.append(RerunSink(rerun, Path(out) / "t.rrd", batch_ticks=1000 if fast else 20))
        clock = SimulatedClock() if fast else MonotonicClock()
        loop = ControlLoop(plant, controllers, {"a": ref, "b": ref}, sinks, now_s=clock.now_s,
                           voltage_limit_v=controller.voltage_limit_v, period_s=plant.period_s)  # fmt: skip
        executor = PeriodicExecutor(plant.period_s, clock, max_ticks=n)
        instrument(loop, timers)
        inner = timers.wrap("loop", loop.tick)

        def tick(k: int) -> bool:
            keep = inner(k, executor.period_error_us, executor.start_s, executor.grid_index * plant.period_s)  # fmt: skip
            timers.close_tick()
            return keep

        scheduling = "simulated clock" if fast else enable_realtime()
        try:
            with gc_paused(quick_gil=True):  # as run's loop
                loop.start()
                executor.run(tick, timers.wrap("idle", loop.idle))
        finally:
            loop.finish()
            restore()
    samples = {p: np.frombuffer(a, dtype=np.float64).copy() for p, a in timers.samples.items()}
    stats = executor.stats()
    inside = (
        "plant",
        "controller",
        "sink csv",
        "sink memory",
        "sink rerun",
    )  # estimator: in controller
    whole_loop = samples["loop"]
    samples["tick"] = np.frombuffer(executor._compute_us, dtype=np.float64)[: whole_loop.size]
    samples["loop"] = whole_loop - sum(samples[p] for p in inside)
    samples["controller"] = samples["controller"] - samples["estimator"]
    samples["executor"] = samples["tick"] - whole_loop  # with this script's bookkeeping
    samples["period error"] = np.frombuffer(executor._period_error_us, dtype=np.float64)[
        : whole_loop.size
    ]
    print(f"  ({scheduling}; {stats.ticks} ticks, {stats.misses} deadline misses)")
    return samples


def print_breakdown(samples: dict[str, np.ndarray]) -> None:
    """The table of parts, and which part dominates the ticks above the tick's p99."""
    print(f"  {'part':<14}{'p50':>9}{'p99':>9}{'max':>9}   (µs per tick)")
    for part in PARTS:
        s = samples[part]
        if s.size and s.max() > 0.0:
            p50, p99 = np.percentile(s, [50, 99])
            print(f"  {part:<14}{p50:>9.1f}{p99:>9.1f}{s.max():>9.1f}")
    tick = samples["tick"]
    slow = np.flatnonzero(tick > np.percentile(tick, 99))
    if slow.size:
        parts = [p for p in PARTS if p not in ("tick", "idle")]
        worst = [max(parts, key=lambda p, i=i: samples[p][i]) for i in slow]
        counts = {p: worst.count(p) for p in parts if worst.count(p)}
        text = ", ".join(f"{p} {c}" for p, c in sorted(counts.items(), key=lambda x: -x[1]))
        print(f"  the {slow.size} ticks above the tick's p99: the largest part was {text}")


def print_late(
    samples: dict[str, np.ndarray], late_us: float = 1000.0, period_us: float = 1e4
) -> None:
    """Each tick that started more than ``late_us`` late, with what ran before it.

    A tick starts late either because the work before it (the previous tick, then the sinks'
    ``idle``) ran past its deadline, or because the thread woke late from its wait: the first is
    this process's doing, the second the operating system's or the hypervisor's.
    """
    err = samples["period error"]
    late = np.flatnonzero(err > late_us)
    if not late.size:
        print(f"  no tick started more than {late_us / 1e3:g} ms late")
        return
    for i in late[:20]:
        # the previous tick's start (after its deadline), its compute, the idle work after it
        done_us = err[i - 1] + samples["tick"][i - 1] + samples["idle"][i] if i else 0.0
        cause = (
            "the work before it ran late" if done_us >= period_us else "it woke late from its wait"
        )
        print(f"  tick {i} started {err[i] / 1e3:.2f} ms late; before it: the tick {samples['tick'][i - 1]:.0f} µs"
              f" and idle {samples['idle'][i]:.0f} µs, so {cause}")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--plant", default="physics", choices=("sim", "physics"))
    parser.add_argument("--controller", default="controllers/poles.toml")
    parser.add_argument("--rerun", default="save", choices=("save", "off"))
    parser.add_argument("--fast", action="store_true", help="on a simulated clock")
    parser.add_argument("--busy", action="store_true", help="keep one other core busy meanwhile")
    args = parser.parse_args(argv)
    print(f"tick breakdown: {args.controller} on {args.plant}, Rerun {args.rerun}, "
          f"{args.seconds:g} s {'simulated' if args.fast else 'real time'}")  # fmt: skip
    busy = busy_core() if args.busy else None  # one other core busy, as bench_run.py --soak
    try:
        samples = measure(args.seconds, args.plant, args.controller, args.rerun, args.fast)
    finally:
        if busy is not None:
            busy.kill()
    print_breakdown(samples)
    print_late(samples)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
