"""The speeds the test suite does not assert: decoding, the real-time grid, the cart's watchdog,
noticing a fault, a monitor's fault and a silent port.

The tests check what happens (every frame decoded, the grid never early, the watchdog trips and
the motors stay at 0 V, the fault is one line with readable files); how fast it happens depends on
the machine and its load, so it is measured here and printed beside its target:

    python benchmarks/bench_speeds.py [--repeat 3] [--busy]

``--busy`` keeps one other core spinning meanwhile (a loaded 2-core machine). Each real-time
figure is the worst of ``--repeat`` tries.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from cartctl.cli import main
from cartctl.errors import PlantError
from cartctl.link.dialect import Encoder, Framer
from cartctl.link.serial_cart import SerialCart
from cartctl.link.virtual_cart import CartFaults, VirtualCart
from cartctl.runtime.executor import MonotonicClock, PeriodicExecutor

GPIO_ARGS = (123_456, [1.5, -2.25, 3.0, 0.0, 12.0, -12.0, 0.125, 1e3], [7, -8, 9, 32_767])


def framer_decode_us(n: int = 20_000) -> float:
    """Mean time to decode one 60-byte GPIO frame fed on its own (µs)."""
    frame = Encoder().gpio(*GPIO_ARGS)
    framer = Framer()
    start = time.perf_counter()
    for _ in range(n):
        framer.feed(frame)
    return (time.perf_counter() - start) / n * 1e6


def executor_grid_s() -> float:
    """Wall time of 20 ticks at 10 ms on the monotonic clock (s): 0.19 at best."""
    executor = PeriodicExecutor(0.01, MonotonicClock(), max_ticks=20)
    start = time.perf_counter()
    executor.run(lambda k: True)
    return time.perf_counter() - start


def watchdog_ms() -> float:
    """From the host's last byte through the line to the first tick with 0 V on the motors (ms)."""
    with VirtualCart(seed=2) as cart:
        plant = SerialCart(cart.port, on_print=lambda line: None)
        plant.reset()
        for _ in range(40):
            plant.step(3.0, -3.0)
        time.sleep(0.5)  # the host is silent, the port stays open
        last_byte = cart.last_host_byte_at_s
        log = list(cart.applied_log)
        plant.link.close()
    assert last_byte is not None
    off = next(t for t, a, b in log if t > last_byte and a == 0.0 and b == 0.0)
    return (off - last_byte) * 1e3


def fault_notice_ms(fault: str) -> float:
    """From an injected fault on the virtual cart to the serial plant's PlantError (ms)."""
    with VirtualCart(faults=CartFaults.parse(f"{fault}=0.3")) as cart:
        plant = SerialCart(cart.port, on_print=lambda line: None)
        plant.reset()
        try:
            for _ in range(300):
                plant.step(1.0, 1.0)
        except PlantError:
            noticed = time.perf_counter()
        else:
            raise SystemExit(f"{fault}: the plant never noticed")
        plant.close()
    assert cart.fault_at_s is not None
    return (noticed - cart.fault_at_s) * 1e3


def _quiet(*argv: str) -> int:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return main(list(argv))


def monitor_pull_s() -> float:
    """Wall time of ``cartctl monitor virtual:pull=0.5 --duration 5`` (s): the fault ends it."""
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        code = _quiet("monitor", "virtual:pull=0.5", "--duration", "5", "--rerun", "save",
                      "--out", tmp, "--name", "f", "--json")  # fmt: skip
        elapsed = time.perf_counter() - start
    assert code == 1
    return elapsed


def silent_port_s() -> float:
    """Wall time of ``cartctl monitor`` on a port that never answers, --connect-timeout 0.3 (s)."""
    master, slave = os.openpty()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            code = _quiet("monitor", f"serial:{os.ttyname(slave)}", "--connect-timeout", "0.3",
                          "--out", tmp)  # fmt: skip
            elapsed = time.perf_counter() - start
    finally:
        os.close(master)
        os.close(slave)
    assert code == 1
    return elapsed


@contextlib.contextmanager
def busy_core(on: bool) -> Iterator[None]:
    """One process spinning on a core meanwhile (nothing when ``on`` is False)."""
    if not on:
        yield
        return
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        spinner.kill()
        spinner.wait()


CHECKS: list[tuple[str, Callable[[], float], str, str]] = [
    ("framer: one GPIO frame decoded", framer_decode_us, "µs", "< 100"),
    ("executor: 20 ticks of 10 ms", executor_grid_s, "s", "0.19 .. 0.5"),
    ("virtual cart: watchdog after the last byte", watchdog_ms, "ms", "70 .. 100"),
    ("serial plant: notices a pulled cable", lambda: fault_notice_ms("pull"), "ms", "< 200"),
    ("serial plant: notices a stall", lambda: fault_notice_ms("stall"), "ms", "< 200"),
    ("monitor: pulled cable at 0.5 s ends it", monitor_pull_s, "s", "< 3"),
    ("monitor: silent port, 0.3 s timeout", silent_port_s, "s", "< 2"),
]


def main_bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="tries per figure (the worst shown)")
    parser.add_argument("--busy", action="store_true", help="keep one other core spinning")
    args = parser.parse_args()
    print(f"{'check':<46}{'worst':>10}  {'unit':<4}{'target':>14}   (one core busy: {args.busy})")
    with busy_core(args.busy):
        for name, measure, unit, target in CHECKS:
            try:
                worst = max(measure() for _ in range(max(1, args.repeat)))
            except PlantError as exc:  # a real-time cart this machine could not keep up with
                print(f"{name:<46}{'failed':>10}  {unit:<4}{target:>14}   {exc}")
                continue
            print(f"{name:<46}{worst:>10.3g}  {unit:<4}{target:>14}", flush=True)


if __name__ == "__main__":
    os.chdir(Path(__file__).resolve().parents[1])
    main_bench()
