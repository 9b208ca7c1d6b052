"""The real loop, measured: ``cartctl run`` in real time and ``--fast``, beside a naive sleep loop.

Run: ``python benchmarks/bench_run.py [--seconds 60]`` from the repository root (it uses the
shipped controllers and model). It prints, for a real-time run of ``--seconds`` each:

- ``cartctl run --rerun off`` and ``--rerun save`` (the loop with and without Rerun recording),
- ``--rerun save`` with a second core kept busy by a spinning process,
- ``poles.toml`` on the physics plant with Rerun recording,
- a naive ``time.sleep(period)`` loop doing a comparable amount of work, in this process (the
  baseline),

the period error p50/p99/max (µs, against the absolute 10 ms grid), deadline misses and the
per-tick compute time; then where a tick's time goes, part by part (``tick_breakdown.py``), for
both shipped on-board controllers on the physics plant; then the ``--fast`` speed-up over real
time for both controllers on both simulators, measured from outside as the wall-time difference
between a 600 s and a 6 s simulated run (which removes start-up costs), against the goal of
2000×; and, in this process, the fast loop alone and with each sink (``fast_parts.py``).

``python benchmarks/bench_run.py --soak MINUTES`` runs the long test instead: ``poles.toml`` on the
physics plant for MINUTES in real time with Rerun recording and one other core busy, and prints
its deadline misses, period error and compute time, with the CPU time the hypervisor stole
meanwhile (on a virtual machine: outliers no guest can prevent). A thread of this process reads
the steal counter of each CPU every 20 ms and the trace file's growth meanwhile; the growth puts
the trace's ticks on this process's clock, so the soak lists each step of steal on the trace's
time axis and, for every tick that started more than 1 ms late, the steal around it, with the
chance that a window placed at random would have held a step; where ``cyclictest`` is installed
it runs alongside, and its thread on the other CPU says whether the machine stalled at the same
moment (``soak_watch.py``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_loop import busy_core, make_work, run_naive
from fast_parts import report as fast_parts_report
from soak_watch import Cyclictest, StealWatch, late_ticks_and_steal, report_cyclictest
from tick_breakdown import measure, print_breakdown


def cartctl_run(seconds: float, *extra: str, out: str | None = None) -> dict:
    """One ``cartctl run --json`` in a subprocess (files to ``out``, else a scratch folder)."""
    with tempfile.TemporaryDirectory() as scratch:
        cmd = [sys.executable, "-m", "cartctl", "run", "--duration", str(seconds),
               "--out", out or scratch, "--json", *extra]  # fmt: skip
        proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(proc.stdout)


def wall_s(*argv: str) -> float:
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        subprocess.run(
            [sys.executable, "-m", "cartctl", "run", "--out", out, *argv],
            capture_output=True,
            check=True,
        )
    return time.perf_counter() - t0


def row(name: str, s: dict) -> str:
    pe, cu = s["period_error_us"], s["compute_us"]
    return (
        f"{name:<34}{s['ticks']:>7}{pe['p50']:>10.1f}{pe['p99']:>10.1f}{pe['max']:>10.1f}"
        f"{s['deadline_misses']:>8}{cu['p50']:>12.1f}{cu['p99']:>12.1f}"
    )


def soak(minutes: float) -> int:
    """The long real-time run: poles.toml on physics, Rerun recording, one other core busy."""
    seconds = minutes * 60.0
    print(f"soak: controllers/poles.toml on physics, {minutes:g} min real time, Rerun recording, "
          "one other core busy")  # fmt: skip
    busy = busy_core()
    with tempfile.TemporaryDirectory() as out:
        try:
            with Cyclictest() as cyc, StealWatch(Path(out) / "soak.csv") as watch:
                s = cartctl_run(seconds, "--plant", "physics", "--controller",
                                "controllers/poles.toml", "--rerun", "save", "--name", "soak",
                                out=out)  # fmt: skip
        finally:
            busy.kill()
        stolen = watch.steal_between(float("-inf"), float("inf")).sum()
        pe, cu = s["period_error_us"], s["compute_us"]
        print(
            f"  ticks {s['ticks']}, deadline misses {s['deadline_misses']} (goal 0), skipped "
            f"deadlines {s['skipped_deadlines']}, miss ticks {s['miss_ticks'][:10]}"
        )
        print(
            f"  period error p50/p99/max {pe['p50']:.1f}/{pe['p99']:.1f}/{pe['max']:.1f} µs "
            f"(goal max <= 1000 µs: {'met' if pe['max'] <= 1000 else 'missed'})"
        )
        print(
            f"  compute p50/p99/max {cu['p50']:.1f}/{cu['p99']:.1f}/{cu['max']:.1f} µs "
            f"(goal p99 <= 200 µs: {'met' if cu['p99'] <= 200 else 'missed'})"
        )
        print(
            f"  CPU time stolen by the hypervisor meanwhile: {stolen:.0f} ms  [{s['scheduling']}]"
        )
        tick0, late_at_s = late_ticks_and_steal(Path(out) / "soak.csv", watch)
        report_cyclictest(cyc, tick0, late_at_s)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--seconds", type=float, default=60.0, help="length of each real-time run (default 60)"
    )
    parser.add_argument("--soak", type=float, metavar="MINUTES", help="run the long test only")
    args = parser.parse_args()
    if args.soak is not None:
        return soak(args.soak)
    print(f"{'variant':<34}{'ticks':>7}{'err p50':>10}{'err p99':>10}{'err max':>10}{'misses':>8}"
          f"{'compute p50':>12}{'compute p99':>12}   (µs)")  # fmt: skip
    off = cartctl_run(args.seconds, "--rerun", "off")
    print(row("cartctl run, no Rerun", off), f"  [{off['scheduling']}]")
    save = cartctl_run(args.seconds, "--rerun", "save")
    print(row("cartctl run, Rerun recording", save))
    busy = busy_core()
    try:
        loaded = cartctl_run(args.seconds, "--rerun", "save")
    finally:
        busy.kill()
    print(row("cartctl run, Rerun, busy core", loaded))
    poles = cartctl_run(args.seconds, "--plant", "physics", "--controller",
                        "controllers/poles.toml", "--rerun", "save")  # fmt: skip
    print(row("poles.toml, physics, Rerun", poles))
    naive = run_naive(make_work(save["compute_us"]["p50"]), 0.01, args.seconds)
    p50, p99, mx = naive.err_us
    print(f"{'naive time.sleep(period) loop':<34}{naive.ticks:>7}{p50:>10.1f}{p99:>10.1f}{mx:>10.1f}"
          f"{'-':>8}{naive.compute_p50_us:>12.1f}{'':>12}   ({naive.skipped} ticks)")  # fmt: skip
    for controller in ("controllers/pi.toml", "controllers/poles.toml"):
        print(f"\ntick breakdown: {controller} on physics, Rerun recording, {args.seconds:g} s")
        print_breakdown(measure(args.seconds, "physics", controller, "save", fast=False))
    print(
        "\n--fast (Rerun recording on), best of 3: wall time of a 6 s and a 600 s run, and the "
        "speed-up over real time of the 594 s between them (goal 2000×)"
    )
    for controller in ("pi", "poles"):
        for plant in ("sim", "physics"):
            argv = ("--fast", "--plant", plant, "--controller", f"controllers/{controller}.toml")
            short = min(wall_s(*argv, "--duration", "6") for _ in range(3))
            long = min(wall_s(*argv, "--duration", "600") for _ in range(3))
            ratio = 594.0 / (long - short)
            print(
                f"  {controller + '.toml':<12}{plant:<9}{short:6.2f} s {long:6.2f} s  "
                f"{ratio:6.0f}× real time  ({ratio / 2000:.2f} of the goal)"
            )
    print(
        "\n--fast, where a tick's time goes: the loop alone, with each sink, with all (fast_parts.py)"
    )
    fast_parts_report(120.0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
