"""The PC loop's tick budget on the virtual cart: where the 10 ms of a serial tick go.

Drives the virtual cart (bridge version 2, 500 kbaud) through the real serial path for a number of
ticks with a simple proportional law (the timing, not the control, is measured here), and prints,
per variant, percentiles (p50 / p99 / max, ms) of each leg of one tick, from the start of the
cart's tick:

- ``cart frame out``: the cart's GPIO through the AVR's UART (io() and control() take 1.2 ms, then
  60 bytes at 500 kbaud);
- ``at the PC``: when the PC's port has it (the ATmega16U2 holds it until its next 4.096 ms flush,
  then the next 1 ms USB frame; ``usb=off``: a bare pseudo-terminal);
- ``host reply``: from the frame's arrival to the reply written (the host's own latency);
- ``reply at the cart``: the reply's last byte through the cart's UART (the next USB frame, then
  60 bytes at 500 kbaud);
- ``margin``: what is left of the tick before the drain that precedes the next ``io()``; a
  negative margin is a reply that misses its tick (it acts one tick later).

It also prints the loop delay the echo gave, the host's frames the cart counted as lost and the
cart's ticks the host skipped. With ``--busy`` one other core spins during the run.

    python benchmarks/bench_tick_budget.py [--ticks 1000] [--busy]
"""

from __future__ import annotations

import argparse
import subprocess
import sys

import numpy as np

from cartctl.plants.factory import make_plant

PERIOD_S = 0.01
VARIANTS = (("USB bridge modelled", "virtual"), ("bare pseudo-terminal", "virtual:usb=off"))


def _run(spec: str, ticks: int) -> dict[str, object]:
    plant, _ = make_plant(spec, seed=1)
    cart = plant.cart  # type: ignore[attr-defined]
    on_print = plant.link.on_print  # type: ignore[attr-defined]
    plant.link.on_print = lambda line: None  # type: ignore[attr-defined]
    try:
        delay = plant.measure_loop_delay()  # type: ignore[attr-defined]
        y = plant.reset()
        first_tick = plant.sample.cart_tick  # type: ignore[attr-defined]
        arrivals = []
        for _ in range(ticks):
            u = max(-12.0, min(12.0, 0.4 * (8.0 - y.speed_a_rad_s)))
            plant.send(u, u)  # type: ignore[attr-defined]
            arrivals.append(plant.arrival_s)  # type: ignore[attr-defined]
            y = plant.receive()  # type: ignore[attr-defined]
        link = plant.link_summary()  # type: ignore[attr-defined]
        latency_ms = 1e3 * np.array(plant.reply_latency_s)  # type: ignore[attr-defined]
    finally:
        plant.link.on_print = on_print  # type: ignore[attr-defined]
        plant.close()
    boot = cart.boot_s
    tick_of = lambda t: np.floor((np.asarray(t) - boot) / PERIOD_S)  # noqa: E731
    out = np.array(cart._writer.deliveries)  # (through the AVR's UART, at the PC)
    out = out[tick_of(out[:, 0]) >= 0]
    start = boot + tick_of(out[:, 0]) * PERIOD_S
    through = np.array(cart._reader.through_s)
    through = through[through > arrivals[0]]
    reply_start = boot + tick_of(np.array(arrivals)) * PERIOD_S
    n = min(len(through), len(reply_start))
    reply_ms = 1e3 * (through[:n] - reply_start[:n])
    return {
        "delay": delay,
        "cart frame out": 1e3 * (out[:, 0] - start),
        "at the PC": 1e3 * (out[:, 1] - start),
        "host reply": latency_ms,
        "reply at the cart": reply_ms,
        "margin": 1e3 * PERIOD_S - reply_ms,
        "lost": link["link"]["host_frames_lost"],
        "skipped": link["link"]["skipped_ticks"],
        "first_tick": first_tick,
    }


def _row(name: str, values: np.ndarray) -> str:
    # the margin's bad tail is its low end: its "p99" is the 1st percentile
    p50, p99 = np.percentile(values, [50, 1 if name == "margin" else 99])
    worst = values.min() if name == "margin" else values.max()
    label = "min" if name == "margin" else "max"
    return f"  {name:<20}{p50:>8.2f}{p99:>8.2f}   {label} {worst:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=1000)
    parser.add_argument("--busy", action="store_true", help="spin one other core during the run")
    args = parser.parse_args()
    burner = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.busy else None
    try:
        for title, spec in VARIANTS:
            r = _run(spec, args.ticks)
            print(f"{title} ({spec}), {args.ticks} ticks{', one core busy' if burner else ''}:")
            print(f"  {'leg (ms into the tick)':<20}{'p50':>8}{'p99':>8}   (margin: p1, min)")
            for leg in ("cart frame out", "at the PC", "host reply", "reply at the cart", "margin"):
                print(_row(leg, np.asarray(r[leg], dtype=float)))
            missed = int(np.sum(np.asarray(r["margin"]) < 0))
            print(f"  loop delay {r['delay']} tick(s); replies that missed their tick: {missed}; "
                  f"host frames lost: {r['lost']}; cart ticks skipped by the host: {r['skipped']}")  # fmt: skip
    finally:
        if burner is not None:
            burner.kill()


if __name__ == "__main__":
    main()
