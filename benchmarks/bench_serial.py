"""The PC-side loop through the serial path: timing, loop delay and fault counts against the virtual cart.

Runs ``cartctl run --plant virtual[:faults]`` for a few seconds per variant (real time: the cart
ticks every 10 ms) with the shipped controllers/pi.toml, designed for its loop delay of 1 tick,
and prints per variant the measured loop delay, the period error (arrival jitter of the cart's
GPIO on the host) and compute percentiles, the link's fault counts and the tracking figures. A variant with a busy core shows
what a loaded PC does to the line timing.

    python benchmarks/bench_serial.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

VARIANTS = [
    ("clean line", "virtual", False),
    ("5 % garbage + 5 % corrupted", "virtual:garbage=0.05,corrupt=0.05", False),
    ("clean line, one core busy", "virtual", True),
]


def _cartctl(*argv: str, cwd: Path) -> dict:
    result = subprocess.run([sys.executable, "-m", "cartctl", *argv], cwd=cwd, capture_output=True,
                            text=True, check=False)  # fmt: skip
    if result.returncode != 0:
        raise SystemExit(f"cartctl {' '.join(argv)} failed:\n{result.stderr}")
    return json.loads(result.stdout) if result.stdout.strip().startswith("{") else {}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        controller = ROOT / "controllers/pi.toml"  # the virtual cart's loop delay is 1 tick
        print(f"{'variant':<30}{'delay':>6}{'pe p50/p99/max µs':>22}{'compute p50/p99 µs':>20}"
              f"{'crc':>5}{'garb B':>8}{'lost':>6}{'ss err a':>10}{'overshoot a':>13}")  # fmt: skip
        for name, plant, busy in VARIANTS:
            burner = None
            if busy:
                burner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
            try:
                s = _cartctl("run", "--plant", plant, "--seed", "1", "--controller", str(controller),
                             "--reference", "step:8", "--duration", str(args.seconds), "--rerun",
                             "save", "--out", str(work / "logs"), "--json", cwd=work)  # fmt: skip
            finally:
                if burner is not None:
                    burner.kill()
            pe, cu, link, a = s["period_error_us"], s["compute_us"], s["link"], s["motors"]["a"]
            print(f"{name:<30}{s['loop_delay_ticks']:>6}"
                  f"{pe['p50']:>8.0f}/{pe['p99']:>5.0f}/{pe['max']:>6.0f}"
                  f"{cu['p50']:>12.0f}/{cu['p99']:>6.0f}"
                  f"{link['crc_errors']:>5}{link['garbage_bytes']:>8}{link['lost_frames']:>6}"
                  f"{a['steady_state_error']:>10.3f}{a['overshoot_percent']:>12.1f}%")  # fmt: skip


if __name__ == "__main__":
    main()
