"""What the soak of ``bench_run.py --soak`` watches besides the loop: the hypervisor's steal per
CPU and the operating system's own wake-up latency, on the trace's time axis.

A tick that starts late has either run late itself (the tick and the sinks' idle work before it)
or woken late from its wait. ``tick_breakdown.py`` tells those apart inside one process; this
module tells the machine's stalls from the loop's from outside: :class:`StealWatch` samples
``/proc/stat`` and ties the trace's ticks to this process's clock by the trace file's growth, and
:class:`Cyclictest` runs ``cyclictest`` (Debian's rt-tests, where installed) alongside, whose
thread on the other CPU shares nothing with the loop.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from bench_loop import steal_ms_by_cpu


class StealWatch:
    """A thread sampling the hypervisor's steal counter per CPU and the growth of a trace file.

    Every ``every_s`` it reads ``/proc/stat`` (steal per CPU, in 10 ms steps) and the size of
    ``trace``, both against :func:`time.perf_counter` (``CLOCK_MONOTONIC``, the clock the loop in
    the other process also reads). The file's growth ties the trace's tick numbers to this clock:
    a row on disk at time t was ticked before t, so ``min(t - tick * period)`` over the samples
    bounds the wall time of tick 0 to within the sampling step and the CSV block's lag.
    """

    def __init__(self, trace: Path, every_s: float = 0.02) -> None:
        self.trace, self.every_s = trace, every_s
        self.steal: list[tuple[float, list[float]]] = []  # (t, steal ms per CPU)
        self.sizes: list[tuple[float, int]] = []  # (t, bytes on disk) where the size changed
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> StealWatch:
        self.started_s = time.perf_counter()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.ended_s = time.perf_counter()
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        last = -1
        while not self._stop.wait(self.every_s):
            t = time.perf_counter()
            by_cpu = steal_ms_by_cpu()
            self.steal.append((t, [ms for cpu, ms in by_cpu.items() if cpu != "cpu"]))
            try:
                size = self.trace.stat().st_size
            except OSError:
                continue
            if size != last:
                self.sizes.append((t, size))
                last = size

    def tick0_s(self, row_ends: np.ndarray, period_s: float) -> float:
        """The bound on tick 0's wall time from the file's growth (``row_ends``: bytes per row)."""
        best = float("inf")
        for t, size in self.sizes:
            rows = int(np.searchsorted(row_ends, size, side="right"))  # complete rows on disk
            if rows:
                best = min(best, t - (rows - 1) * period_s)
        return best

    def steal_between(self, t0: float, t1: float) -> np.ndarray:
        """Steal per CPU (ms) between the last sample before t0 and the first after t1."""
        times = np.array([t for t, _ in self.steal])
        counts = np.array([c for _, c in self.steal])
        i = max(int(np.searchsorted(times, t0)) - 1, 0)
        j = min(int(np.searchsorted(times, t1)), len(times) - 1)
        return counts[j] - counts[i]


def late_ticks_and_steal(
    trace: Path, watch: StealWatch, period_s: float = 0.01
) -> tuple[float, list[float]]:
    """Print the steal steps on the trace's time axis, and each tick more than 1 ms late with the
    steal around it (to tell the hypervisor's stalls from the guest's)."""
    ends = np.flatnonzero(np.frombuffer(trace.read_bytes(), dtype=np.uint8) == ord("\n")) + 1
    table = np.genfromtxt(trace, delimiter=",", names=True)
    tick0 = watch.tick0_s(ends[1:], period_s)  # the first newline ends the header
    times = np.array([t for t, _ in watch.steal])
    counts = np.array([c for _, c in watch.steal])
    steps = np.flatnonzero(np.diff(counts.sum(axis=1)) > 0) + 1
    print(f"  steal, read every {watch.every_s * 1e3:.0f} ms: {len(steps)} steps")
    last_s = tick0 + table["tick"][-1] * period_s
    print(f"  the trace tied to this clock by its growth ({len(watch.sizes)} samples): tick 0 "
          f"{tick0 - watch.started_s:.2f} s after the command started, the last tick "
          f"{watch.ended_s - last_s:.2f} s before it ended")  # fmt: skip
    for k in steps[:20]:
        grew = counts[k] - counts[k - 1]
        cpus = ", ".join(f"cpu{c} {v:.0f} ms" for c, v in enumerate(grew) if v > 0)
        print(f"    at {times[k] - tick0:8.2f} s of the trace: {cpus}")
    late = np.flatnonzero(table["period_error_us"] > 1000.0)
    near = 0
    late_at_s = []
    for i in late:
        t = tick0 + table["tick"][i] * period_s + table["period_error_us"][i] * 1e-6
        late_at_s.append(t)
        around = watch.steal_between(t - 1.0, t + 0.5)
        near += bool(around.sum() > 0)
        print(f"  tick {int(table['tick'][i])} ({table['time_s'][i]:.2f} s) started "
              f"{table['period_error_us'][i] / 1e3:.1f} ms late; steal from 1 s before to 0.5 s "
              f"after: {', '.join(f'cpu{c} {v:.0f} ms' for c, v in enumerate(around))}")  # fmt: skip
    if len(late):
        span = times[-1] - times[0]
        chance = min(1.0, len(steps) * (1.5 + watch.every_s) / span)
        print(f"  {near} of {len(late)} late ticks had steal in that window; a window placed at "
              f"random holds a steal step with probability about {chance:.2f}")  # fmt: skip
    else:
        print("  no tick started more than 1 ms late")
    return tick0, late_at_s


class Cyclictest:
    """``cyclictest`` (Debian's rt-tests) alongside, when installed: the operating system's own
    wake-up latency at the same time, one SCHED_FIFO thread per CPU at priority 49 (below the
    loop's 50) waking every 10 ms. A late tick of the loop that these threads also saw is the
    machine's; one they did not see is the loop's own.
    """

    def __init__(self) -> None:
        self.path = shutil.which("cyclictest")
        self.proc: subprocess.Popen[bytes] | None = None

    def __enter__(self) -> Cyclictest:
        if self.path:
            self._out = tempfile.TemporaryFile()
            self.started_s = time.perf_counter()
            self.proc = subprocess.Popen(
                [self.path, "-m", "-p", "49", "-i", "10000", "-d", "0", "-t", "-a", "-v",
                 "--laptop"],  # --laptop: leave /dev/cpu_dma_latency alone (the loop's conditions)
                stdout=self._out, stderr=subprocess.DEVNULL,
            )  # fmt: skip
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc is not None:
            self.proc.send_signal(signal.SIGINT)
            self.proc.wait(timeout=10)

    def latencies_us(self) -> list[np.ndarray]:
        """Wake-up latency (µs) per loop, one array per thread (CPU); loop i woke at about
        ``started_s + (i + 1) * 10 ms``."""
        if self.proc is None:
            return []
        self._out.seek(0)
        rows = [ln.split(":") for ln in self._out.read().decode().splitlines()]
        table = np.array([[int(f) for f in r] for r in rows if len(r) == 3], dtype=np.int64)
        if not table.size:
            return []
        out = []
        for thread in range(int(table[:, 0].max()) + 1):
            mine = table[table[:, 0] == thread]
            lat = np.full(int(mine[:, 1].max()) + 1, np.nan)
            lat[mine[:, 1]] = mine[:, 2]
            out.append(lat)
        return out


def report_cyclictest(
    cyc: Cyclictest, tick0_s: float, late_at_s: list[float], late_us: float = 1000.0
) -> None:
    """The OS's wake-up latency beside the loop's: overall (on the trace's time axis, tick 0 at
    ``tick0_s``), and around each late tick. On the loop's own CPU its wake-ups also wait for the
    loop's tick and idle work (up to a few ms); on the other CPU they do not."""
    if cyc.proc is None:
        print("  (cyclictest not installed: apt install rt-tests, to see the OS's own wake-ups)")
        return
    lats = cyc.latencies_us()
    for cpu, lat in enumerate(lats):
        big = np.flatnonzero(lat > late_us)
        at = cyc.started_s - tick0_s
        when = ", ".join(f"{at + (i + 1) * 0.01:.2f} s ({lat[i] / 1e3:.1f} ms)" for i in big[:10])
        print(f"  cyclictest cpu{cpu}: {np.count_nonzero(~np.isnan(lat))} wake-ups, p50/p99/max "
              f"{np.nanpercentile(lat, 50):.0f}/{np.nanpercentile(lat, 99):.0f}/{np.nanmax(lat):.0f}"
              f" µs, {big.size} over {late_us / 1e3:g} ms{': at ' + when if big.size else ''} "
              f"(on the trace's time axis)")  # fmt: skip
    for t in late_at_s:
        k = round((t - cyc.started_s) / 0.01) - 1
        near = [np.nanmax(lat[max(k - 50, 0) : k + 51], initial=0.0) for lat in lats]
        print(f"  around the late tick at {t - tick0_s:.2f} s (±0.5 s): cyclictest's worst wake-up "
              f"{', '.join(f'cpu{c} {v / 1e3:.2f} ms' for c, v in enumerate(near))}")  # fmt: skip
