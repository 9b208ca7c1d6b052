"""Ctrl-C while ``cartctl`` starts: how often it ends in a traceback, and how long the window is.

Two measurements, both through the installed console script (what a user runs):

1. **Random moments.** ``cartctl --version`` and ``cartctl run --help`` are spawned ``--tries``
   times each and get SIGINT at a uniformly random moment of their first ``--window-ms`` (300 ms).
   Each outcome is counted: a ``Traceback`` on stderr, killed by the signal (the interpreter had
   not installed its own handler yet: exit -2), one line and exit 130 (cartctl's handler), or the
   command finished before the signal (exit 0).
2. **The interpreter's window.** The time from ``exec`` to cartctl's stop handlers, read from a
   copy of the console script that notes ``time.monotonic()`` (one clock for all processes on
   Linux) when the first module after the handlers is imported. Until then a SIGINT meets Python's
   default handler (or none), which cartctl cannot change; after it cartctl answers in one line.

Usage::

    python benchmarks/bench_startup_interrupt.py [--tries 40] [--window-ms 300] [--seed 1]

The figures are in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import collections
import os
import random
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMANDS = (["--version"], ["run", "--help"])
MARK_AFTER = "argparse"
"""The first module ``cartctl.cli`` imports after it installed the stop handlers."""
PRELUDE = f"""\
import sys as _s, time as _t
class _Mark:
    @staticmethod
    def find_spec(name, path=None, target=None):
        if name == {MARK_AFTER!r}:
            _s.stderr.write(f"MARK %r\\n" % _t.monotonic())
            _s.meta_path.remove(_Mark)
_s.meta_path.insert(0, _Mark)
"""


def console_script() -> Path:
    """The ``cartctl`` console script beside this interpreter (the venv's), or on PATH."""
    beside = Path(sys.executable).parent / "cartctl"
    found = beside if beside.exists() else shutil.which("cartctl")
    if found is None:
        raise SystemExit("no cartctl console script: pip install -e . first")
    return Path(found)


def outcome(process: subprocess.Popen[str]) -> str:
    """What one interrupted start ended in."""
    _, err = process.communicate(timeout=60)
    if "Traceback" in err:
        return "traceback"
    if process.returncode == -signal.SIGINT:
        return "killed by SIGINT"
    if process.returncode == 130 and len(err.strip().splitlines()) == 1:
        return "one line, exit 130"
    if process.returncode == 0:
        return "finished first"
    return f"exit {process.returncode}: {err.strip()[:80]!r}"


def random_moments(script: Path, tries: int, window_s: float, rng: random.Random) -> None:
    """SIGINT at random moments of the first ``window_s``; counts per outcome."""
    counts: dict[str, collections.Counter[str]] = {}
    latest_bad: dict[str, float] = {}
    for argv in COMMANDS:
        name = " ".join(argv)
        counts[name] = collections.Counter()
        for _ in range(tries):
            at_s = rng.uniform(0.0, window_s)
            process = subprocess.Popen([sys.executable, str(script), *argv], text=True,
                                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
            time.sleep(at_s)
            process.send_signal(signal.SIGINT)
            result = outcome(process)
            counts[name][result] += 1
            if result in ("traceback", "killed by SIGINT"):
                latest_bad[name] = max(latest_bad.get(name, 0.0), at_s)
    for name, counter in counts.items():
        shown = ", ".join(f"{what} {n}" for what, n in counter.most_common())
        late = latest_bad.get(name)
        tail = f"; latest bad moment {1e3 * late:.0f} ms" if late is not None else ""
        print(f"cartctl {name}: {tries} tries: {shown}{tail}")


def handler_window(script: Path, repeats: int) -> None:
    """Time from spawning the console script to cartctl's stop handlers (ms)."""
    with tempfile.TemporaryDirectory() as folder:
        marked = Path(folder) / "cartctl"
        body = script.read_text(encoding="utf-8").splitlines(keepends=True)
        shebang = body[:1] if body and body[0].startswith("#!") else []
        marked.write_text("".join([*shebang, PRELUDE, *body[len(shebang) :]]), encoding="utf-8")
        spans_ms = []
        for _ in range(repeats):
            start = time.monotonic()
            done = subprocess.run([sys.executable, str(marked), "--version"], text=True,
                                  capture_output=True, check=True)  # fmt: skip
            mark = next(line for line in done.stderr.splitlines() if line.startswith("MARK "))
            spans_ms.append(1e3 * (float(mark.split()[1]) - start))
        spans_ms.sort()
        print(
            f"exec -> stop handlers installed: median {statistics.median(spans_ms):.1f} ms, "
            f"min {spans_ms[0]:.1f}, max {spans_ms[-1]:.1f} ms over {repeats} starts "
            f"({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f})"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tries", type=int, default=40, help="spawns per command (40)")
    parser.add_argument("--window-ms", type=float, default=300.0, help="SIGINT within (300 ms)")
    parser.add_argument("--repeats", type=int, default=20, help="starts timed for the window")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    script = console_script()
    handler_window(script, args.repeats)
    random_moments(script, args.tries, args.window_ms / 1e3, random.Random(args.seed))


if __name__ == "__main__":
    main()
