"""Loop timing at 10 ms: a naive ``time.sleep(period)`` loop against the periodic executor.

Run: ``python benchmarks/bench_loop.py [--seconds 60] [--busy [N]]``. In one process, one after
the other, it runs the same synthetic tick (about 100 µs of numpy) for ``--seconds`` each as:

- ``naive sleep(period)``: work, then ``time.sleep(period)``, the classic drifting loop;
- ``executor, sleep``: absolute deadlines, plain sleep (``MonotonicClock(spin_s=0)``);
- ``executor, sleep+spin``: sleep until 1 ms before the deadline, then spin (the default clock);
- ``executor, sleep+FIFO`` and ``executor, sleep+spin+FIFO``: the same under SCHED_FIFO, where
  permitted (the line printed before the table says what was obtained).

``--busy N`` keeps N other processes spinning meanwhile (one busy core on a 2-core machine for
N = 1). The table gives, per variant, the period error against the absolute grid
t0 + k·period (µs; for the naive loop this includes its accumulated drift), the p99 of the
deviation of each interval from the period, the compute time, deadline misses and skipped
deadlines (executor only; for the naive loop the ticks it fell behind), and the CPU time the
hypervisor stole meanwhile on a virtual machine (/proc/stat, in 10 ms steps: outliers that no
guest-side scheduling can prevent). A last line gives the executor's own cost per tick on a
simulated clock, the bound on the simulated loop's speed-up.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from cartctl.runtime.executor import MonotonicClock, PeriodicExecutor, SimulatedClock
from cartctl.runtime.realtime import enable_realtime, restore


@dataclass(frozen=True)
class Row:
    name: str
    ticks: int
    err_us: tuple[float, float, float]  # p50, p99, max against the absolute grid
    interval_p99_us: float  # p99 of |interval - period|
    compute_p50_us: float
    misses: str
    skipped: str
    steal_ms: float = float("nan")  # time the hypervisor took the CPUs away meanwhile (ms)


def steal_ms_by_cpu() -> dict[str, float]:
    """CPU steal time so far (ms) from /proc/stat (Linux, 10 ms steps): ``"cpu"`` for all CPUs,
    ``"cpu0"``, ``"cpu1"`` ... for each; empty elsewhere."""
    try:
        tick_ms = 1e3 / os.sysconf("SC_CLK_TCK")
        with open("/proc/stat") as f:
            rows = [line.split() for line in f if line.startswith("cpu")]
        return {row[0]: float(row[8]) * tick_ms for row in rows}
    except (OSError, IndexError, ValueError):
        return {}


def steal_ms() -> float:
    """Total CPU steal time so far (ms) from /proc/stat (Linux, 10 ms steps); NaN elsewhere."""
    return steal_ms_by_cpu().get("cpu", float("nan"))


def busy_core() -> subprocess.Popen[bytes]:
    """A process spinning on one core, until killed."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def measured(run: Callable[[], Row]) -> Row:
    """``run()``, with the steal time during it."""
    before = steal_ms()
    row = run()
    return replace(row, steal_ms=steal_ms() - before)


def make_work(target_us: float) -> Callable[[], None]:
    """A numpy workload of about ``target_us`` µs (median), calibrated on this machine."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal((32, 32)) / 8.0
    x0 = rng.standard_normal(32)

    def once(reps: int) -> None:
        x = x0
        for _ in range(reps):
            x = np.tanh(a @ x)

    def median_us(reps: int) -> float:
        times = []
        for _ in range(51):
            t = time.perf_counter()
            once(reps)
            times.append(time.perf_counter() - t)
        return float(np.median(times)) * 1e6

    per_rep_us = median_us(200) / 200
    reps = max(1, round(target_us / per_rep_us))
    return lambda: once(reps)


def grid_row(
    name: str, starts: np.ndarray, ends: np.ndarray, period_s: float, misses: str, skipped: str
) -> Row:
    """Timing of a loop from its tick start and end times (s), against the grid of its first start."""
    n = starts.size
    err_us = (starts - (starts[0] + np.arange(n) * period_s)) * 1e6
    interval_us = np.abs(np.diff(starts) - period_s) * 1e6
    compute_us = (ends - starts) * 1e6
    p50, p99 = np.percentile(err_us, [50, 99])
    return Row(
        name,
        n,
        (float(p50), float(p99), float(err_us.max())),
        float(np.percentile(interval_us, 99)) if n > 1 else float("nan"),
        float(np.median(compute_us)),
        misses,
        skipped,
    )


def run_naive(work: Callable[[], None], period_s: float, seconds: float) -> Row:
    """``work(); time.sleep(period)`` until ``seconds`` have passed."""
    clock = time.perf_counter
    n_max = int(seconds / period_s) + 10
    starts, ends = np.empty(n_max), np.empty(n_max)
    t_end = clock() + seconds
    n = 0
    while n < n_max:
        s = clock()
        if s >= t_end:
            break
        work()
        starts[n], ends[n] = s, clock()
        n += 1
        time.sleep(period_s)
    starts, ends = starts[:n], ends[:n]
    behind = int((starts[-1] - starts[0]) / period_s) + 1 - n  # grid points passed without a tick
    return grid_row("naive sleep(period)", starts, ends, period_s, "-", f"{behind} behind")


def run_executor(
    name: str, work: Callable[[], None], period_s: float, seconds: float, spin_s: float
) -> Row:
    """The executor on the monotonic clock, ``seconds / period_s`` ticks."""
    n = round(seconds / period_s)
    ex = PeriodicExecutor(period_s, MonotonicClock(spin_s=spin_s), max_ticks=n)
    starts, ends = np.empty(n), np.empty(n)
    clock = time.perf_counter

    def tick(k: int) -> bool:
        work()
        starts[k] = ex.start_s
        ends[k] = clock()
        return True

    stats = ex.run(tick)
    row = grid_row(name, starts, ends, period_s, str(stats.misses), str(stats.skipped_deadlines))
    # the executor's own statistics (on the same grid when nothing was skipped)
    return Row(
        row.name,
        stats.ticks,
        (stats.period_error_us_p50, stats.period_error_us_p99, stats.period_error_us_max),
        row.interval_p99_us,
        stats.compute_us_p50,
        row.misses,
        row.skipped,
    )


def simulated_clock_overhead_us(period_s: float, n: int = 200_000) -> float:
    """Wall time per tick (µs) of the executor on a simulated clock with an empty tick."""
    ex = PeriodicExecutor(period_s, SimulatedClock(), max_ticks=n)
    t = time.perf_counter()
    ex.run(lambda k: True)
    return (time.perf_counter() - t) / n * 1e6


def print_table(rows: list[Row]) -> None:
    head = (
        f"{'variant':<26}{'ticks':>7}{'err p50':>10}{'err p99':>10}{'err max':>10}"
        f"{'|dT-T| p99':>12}{'compute p50':>13}{'misses':>8}{'skipped':>12}{'steal':>7}"
    )
    print(head)
    print(
        f"{'':<26}{'':>7}{'(µs)':>10}{'(µs)':>10}{'(µs)':>10}{'(µs)':>12}{'(µs)':>13}"
        f"{'':>8}{'':>12}{'(ms)':>7}"
    )
    for r in rows:
        p50, p99, mx = r.err_us
        print(
            f"{r.name:<26}{r.ticks:>7}{p50:>10.1f}{p99:>10.1f}{mx:>10.1f}"
            f"{r.interval_p99_us:>12.1f}{r.compute_p50_us:>13.1f}{r.misses:>8}{r.skipped:>12}"
            f"{r.steal_ms:>7.0f}"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="duration per variant (s)")
    parser.add_argument("--period-ms", type=float, default=10.0, help="loop period (ms)")
    parser.add_argument("--work-us", type=float, default=100.0, help="synthetic tick work (µs)")
    parser.add_argument("--spin-ms", type=float, default=1.0, help="spin before each deadline (ms)")
    parser.add_argument("--priority", type=int, default=50, help="SCHED_FIFO priority")
    parser.add_argument(
        "--busy",
        type=int,
        nargs="?",
        const=1,
        default=0,
        metavar="N",
        help="keep N other processes spinning (default 1 when given)",
    )
    args = parser.parse_args(argv)
    if args.seconds <= 0 or args.period_ms <= 0 or args.work_us < 0 or args.busy < 0:
        parser.error("--seconds and --period-ms must be > 0, --work-us and --busy >= 0")
    period_s = args.period_ms / 1e3
    spin_s = args.spin_ms / 1e3
    work = make_work(args.work_us)

    spinners = [busy_core() for _ in range(args.busy)]
    rows: list[Row] = []
    try:
        print(
            f"period {args.period_ms:g} ms, {args.seconds:g} s per variant, "
            f"~{args.work_us:g} µs of work per tick, {args.busy} busy process(es)"
        )
        rows.append(measured(lambda: run_naive(work, period_s, args.seconds)))
        for name, spin in (("executor, sleep", 0.0), ("executor, sleep+spin", spin_s)):
            rows.append(
                measured(lambda n=name, s=spin: run_executor(n, work, period_s, args.seconds, s))
            )
        description = enable_realtime(args.priority)
        print(f"real-time variants: {description}")
        try:
            fifo = "FIFO" if description.startswith("SCHED_FIFO") else "FIFO refused"
            for name, spin in (
                (f"executor, sleep+{fifo}", 0.0),
                (f"executor, sleep+spin+{fifo}", spin_s),
            ):
                rows.append(
                    measured(
                        lambda n=name, s=spin: run_executor(n, work, period_s, args.seconds, s)
                    )
                )
        finally:
            restore()
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    print()
    print_table(rows)
    overhead = simulated_clock_overhead_us(period_s)
    print(
        f"\nsimulated clock: executor overhead {overhead:.2f} µs/tick with an empty tick "
        f"(at most {period_s * 1e6 / overhead:,.0f}x real time before any tick work)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
