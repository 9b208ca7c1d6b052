"""The real loop, measured: ``cartctl run`` in real time and ``--fast``, beside a naive sleep loop.

Run: ``python benchmarks/bench_run.py [--seconds 60]`` from the repository root (it uses the
shipped controller and model). It prints, for a real-time run of ``--seconds`` each:

- ``cartctl run --rerun off`` and ``--rerun save`` (the loop with and without Rerun recording),
- ``--rerun save`` with a second core kept busy by a spinning process,
- a naive ``time.sleep(period)`` loop doing a comparable amount of work, in this process,

the period error p50/p99/max (µs, against the absolute 10 ms grid), deadline misses and the
per-tick compute time; then the ``--fast`` speed-up over real time, measured from outside as the
wall-time difference between a 600 s and a 6 s simulated run (which removes start-up costs).
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
from bench_loop import make_work, run_naive


def cartctl_run(seconds: float, *extra: str) -> dict:
    """One ``cartctl run --json`` in a subprocess; its summary."""
    with tempfile.TemporaryDirectory() as out:
        cmd = [
            sys.executable,
            "-m",
            "cartctl",
            "run",
            "--duration",
            str(seconds),
            "--out",
            out,
            "--json",
            *extra,
        ]
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


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--seconds", type=float, default=60.0, help="length of each real-time run (default 60)"
    )
    args = parser.parse_args()
    print(f"{'variant':<34}{'ticks':>7}{'err p50':>10}{'err p99':>10}{'err max':>10}{'misses':>8}"
          f"{'compute p50':>12}{'compute p99':>12}   (µs)")  # fmt: skip
    off = cartctl_run(args.seconds, "--rerun", "off")
    print(row("cartctl run, no Rerun", off), f"  [{off['scheduling']}]")
    save = cartctl_run(args.seconds, "--rerun", "save")
    print(row("cartctl run, Rerun recording", save))
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        loaded = cartctl_run(args.seconds, "--rerun", "save")
    finally:
        busy.kill()
    print(row("cartctl run, Rerun, busy core", loaded))
    naive = run_naive(make_work(save["compute_us"]["p50"]), 0.01, args.seconds)
    p50, p99, mx = naive.err_us
    print(f"{'naive time.sleep(period) loop':<34}{naive.ticks:>7}{p50:>10.1f}{p99:>10.1f}{mx:>10.1f}"
          f"{'-':>8}{naive.compute_p50_us:>12.1f}{'':>12}   ({naive.skipped} ticks)")  # fmt: skip
    short = min(wall_s("--fast", "--duration", "6") for _ in range(3))
    long = min(wall_s("--fast", "--duration", "600") for _ in range(3))
    print(f"\n--fast: 6 s run {short:.2f} s wall, 600 s run {long:.2f} s wall (best of 3, Rerun recording on): "
          f"{594.0 / (long - short):.0f}× real time")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
