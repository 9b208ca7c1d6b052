"""Start-up time: ``cartctl --help`` and the time from the command to the first tick of a run.

Run: ``python benchmarks/bench_startup.py [--repeat 5]`` from the repository root. It prints, each
as the best of ``--repeat`` fresh processes (wall time, measured from this process):

- ``python -c pass``: the interpreter's own start, the baseline of the same run,
- ``python -m cartctl --help``: argument parsing only, against the goal of 0.3 s,
- ``python -m cartctl run --plant sim --duration 1`` in real time and with ``--fast``: the time
  from the command (the ``Popen`` call) to the loop's first tick, against the goal of 1 s.

The first tick is seen from outside the package: the child is ``python -c`` with a few lines that
wrap :meth:`PeriodicExecutor.run <cartctl.runtime.executor.PeriodicExecutor.run>` and
:meth:`BackToBackExecutor.run <cartctl.runtime.executor.BackToBackExecutor.run>` (``--fast``), in the
child only (nothing in the package is changed), so that the first call of the tick function prints
``time.perf_counter()``, then call :func:`cartctl.cli.main` with the command's arguments.
``perf_counter`` is the system's monotonic clock on Linux, the same in both processes.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time

HELP_GOAL_S = 0.3
FIRST_TICK_GOAL_S = 1.0

# The child of a first-tick measurement: the wrapper first, then the command line as usual.
_CHILD = """
import sys, time
from cartctl.runtime import executor as _ex
def _wrap(cls):
    orig = cls.run
    def _run(self, tick, idle=None):
        seen = []
        def wrapped(k):
            if not seen:
                seen.append(time.perf_counter())
                print(f"FIRST_TICK {seen[0]!r}", file=sys.stderr, flush=True)
            return tick(k)
        return orig(self, wrapped, idle)
    cls.run = _run
_wrap(_ex.PeriodicExecutor)
_wrap(_ex.BackToBackExecutor)
from cartctl.cli import main
raise SystemExit(main(sys.argv[1:]))
"""


def wall_s(argv: list[str]) -> float:
    """Wall time of one subprocess, from ``Popen`` to its exit."""
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def first_tick_s(extra: list[str]) -> float:
    """Seconds from ``Popen`` of ``cartctl run --plant sim --duration 1 EXTRA`` to its first tick."""
    with tempfile.TemporaryDirectory() as out:
        argv = [sys.executable, "-c", _CHILD, "run", "--plant", "sim", "--duration", "1",
                "--rerun", "off", "--out", out, *extra]  # fmt: skip
        t0 = time.perf_counter()
        proc = subprocess.run(argv, check=True, capture_output=True, text=True)
    for line in proc.stderr.splitlines():
        if line.startswith("FIRST_TICK "):
            return float(line.split()[1]) - t0
    raise RuntimeError(f"no first tick seen:\n{proc.stderr}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="processes per figure (best of)")
    args = parser.parse_args()
    n = args.repeat
    base = min(wall_s([sys.executable, "-c", "pass"]) for _ in range(n))
    help_s = min(wall_s([sys.executable, "-m", "cartctl", "--help"]) for _ in range(n))
    real = min(first_tick_s([]) for _ in range(n))
    fast = min(first_tick_s(["--fast"]) for _ in range(n))
    print(f"start-up, best of {n} processes (wall time from the command)")
    print(f"  python -c pass (baseline)                        {base:6.3f} s")
    print(f"  cartctl --help                                   {help_s:6.3f} s   goal {HELP_GOAL_S} s  "
          f"{'met' if help_s <= HELP_GOAL_S else 'MISSED'}")  # fmt: skip
    for name, value in (("real time", real), ("--fast", fast)):
        print(f"  cartctl run --plant sim, first tick ({name + ')':10s} {value:6.3f} s   goal "
              f"{FIRST_TICK_GOAL_S} s  {'met' if value <= FIRST_TICK_GOAL_S else 'MISSED'}")  # fmt: skip


if __name__ == "__main__":
    main()
