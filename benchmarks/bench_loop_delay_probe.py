"""The loop-delay probe under load: ``cartctl run --plant virtual`` with other cores kept busy.

Spawns ``--busy`` processes that spin (one per core to keep busy), then runs
``cartctl run --plant virtual --duration 0.3 --rerun off --json`` ``--tries`` times and counts the
runs by what the probe found: the bridge's loop delay (1 tick) clearly, 1 tick but not clearly
(the run warns and goes on), another delay, or no verdict (the run failed: exit code and line).
Prints each probe's spread and the run's own echoes per delay.

Usage::

    python benchmarks/bench_loop_delay_probe.py [--tries 20] [--busy 1] [--plant virtual]

The figures are in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one_run(folder: Path, plant: str, name: str) -> tuple[str, str]:
    """(verdict, detail) of one run."""
    done = subprocess.run(
        [sys.executable, "-m", "cartctl", "run", "--plant", plant, "--duration", "0.3",
         "--rerun", "off", "--json", "--name", name],
        cwd=folder, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    if done.returncode != 0:
        lines = [line for line in done.stderr.splitlines() if line.startswith("cartctl")]
        # the trace is opened after the probe's verdict: without it, the run failed before
        when = "in the run" if (folder / "logs" / f"{name}.csv").exists() else "before a verdict"
        return f"exit {done.returncode} {when}", lines[-1] if lines else done.stderr[-200:]
    summary = json.loads(done.stdout)
    link = summary["link"]
    probe = link["loop_delay_probe"]
    detail = (
        f"probe {probe['counts']} ({probe['echoes']} echoes); run {link['loop_delay_ticks_seen']}"
    )
    if probe["ticks"] == 1:
        return ("1 tick, clear" if probe["clear"] else "1 tick, not clear (warned, ran)"), detail
    return f"probe {probe['ticks']} ({'clear' if probe['clear'] else 'not clear'})", detail


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tries", type=int, default=20)
    parser.add_argument("--busy", type=int, default=1, help="spinning processes (1)")
    parser.add_argument("--plant", default="virtual")
    args = parser.parse_args()
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
                for _ in range(args.busy)]  # fmt: skip
    verdicts: collections.Counter[str] = collections.Counter()
    try:
        with tempfile.TemporaryDirectory() as name:
            folder = Path(name)
            for sub in ("models", "controllers"):
                shutil.copytree(ROOT / sub, folder / sub)
            for k in range(args.tries):
                verdict, detail = one_run(folder, args.plant, f"probe{k}")
                verdicts[verdict] += 1
                print(f"{k + 1:3d}: {verdict}: {detail}", flush=True)
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
    shown = ", ".join(f"{what} {n}" for what, n in verdicts.most_common())
    print(f"{args.plant}, {args.busy} busy process(es) on {os.cpu_count()} cores: "
          f"{args.tries} runs: {shown}")  # fmt: skip


if __name__ == "__main__":
    main()
