"""Firmware in the loop: the bridge sketch on the course's real microOS, in real time, under cartctl.

The sketch in ``firmware/cartctl_bridge/`` is built for the ATmega2560 with the course's own code
(the Arduino AVR core, the course libraries microOS and components, the template's ``mecotron.h``),
all of it taken from a copy of the course sources outside this repository. The ELF then runs on
simavr's ATmega2560 inside ``tests/fil/cart_sim.c``, cartctl's harness: paced to the wall clock,
UART0 on a pseudo-terminal at the line's byte rate, two DC motors with the ``ground`` preset's
constants behind a TB6612FNG model, and quadrature encoders. ``cartctl run --plant serial:PTY``
then drives it exactly as it drives the cart.

Checked:

- the loop delay cartctl measures (1 tick for bridge version 2, 3 before);
- no host frame lost on the way in (``link.host_frames_lost``) and no byte dropped by the UART;
- the 10 rad/s step tracked with an overshoot below 15 % on both motors;
- the watchdog: a second ``cartctl run`` is killed (SIGKILL, no stop frames) while it drives, and
  the harness measures from the host's last byte to the moment both motors have no voltage
  (within 100 ms).

Run with ``pytest -m fil -s tests/test_firmware_fil.py`` to see the figures; without ``-m fil``
(or ``CARTCTL_FIL=1``) it is skipped, so the default suite stays quick. Needs the course
sources (``CARTCTL_MECOTRON``: a checkout or a git directory of meco-group/mecotron; else
``~/.cache/cartctl/mecotron``, which ``tools/get_mecotron.sh`` fills), the AVR toolchain and
Arduino core (Debian: ``gcc-avr avr-libc arduino-core-avr``), gcc and ``libsimavr-dev``; skipped
with the reason when any is missing. The build is cached in ``~/.cache/cartctl/fil-build``, keyed
by a hash of every input, so a rerun starts at once.

What is a model and not the cart: the motors, bridge and encoders (averaged PWM, no current
ripple, the preset's constants), the pseudo-terminal for the USB cable (the 16U2 bridge only with
``--usb-latency``), and simavr's timing of the UART (exact byte times, no clock error).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

import avr_build

ROOT = Path(__file__).resolve().parents[1]
SKETCH = ROOT / "firmware" / "cartctl_bridge"
FIL = Path(__file__).resolve().parent / "fil"
HARNESS_SOURCE = FIL / "cart_sim.c"
STANDBY_SOURCE = FIL / "hbridge_standby.cpp"
CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cartctl"
COURSE_DEFAULT = CACHE / "mecotron"
BUILD_CACHE = CACHE / "fil-build"
ARDUINO_IN_CHECKOUT = Path("software") / "Arduino"

SERIAL_BUFFERS = ["-DSERIAL_RX_BUFFER_SIZE=256", "-DSERIAL_TX_BUFFER_SIZE=256"]  # or no build
WATCHDOG_BOUND_MS = 100.0
OVERSHOOT_BOUND_PERCENT = 15.0


# -- finding the course sources ---------------------------------------------------------------


def _git(git_dir: Path, *args: str) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(["git", f"--git-dir={git_dir}", *args], capture_output=True, check=False)


def _course_arduino() -> tuple[Path | None, str]:
    """The course's ``software/Arduino`` folder, and where it came from (or None and why not).

    ``CARTCTL_MECOTRON`` (else ``~/.cache/cartctl/mecotron``) is a checkout of the mecotron
    repository, or a git directory (bare, a mirror, or a checkout's ``.git``): then its HEAD's
    ``software/Arduino`` is extracted once into the cache, never into this repository.
    """
    given = os.environ.get("CARTCTL_MECOTRON")
    base = Path(given).expanduser() if given else COURSE_DEFAULT
    how = "CARTCTL_MECOTRON" if given else "the default cache folder"
    if (base / ARDUINO_IN_CHECKOUT / "libraries" / "microOS").is_dir():
        return base / ARDUINO_IN_CHECKOUT, f"{base} ({how})"
    if not base.exists():
        return None, (
            f"the course sources are not at {base} ({how}); run tools/get_mecotron.sh, or set "
            "CARTCTL_MECOTRON to a checkout or git directory of meco-group/mecotron"
        )
    if shutil.which("git") is None:
        return None, f"{base} is no checkout and git is missing to read it as a git directory"
    git_dir = base / ".git" if (base / ".git").exists() else base
    head = _git(git_dir, "rev-parse", "HEAD")
    if head.returncode != 0:
        return None, f"{base} ({how}) holds neither software/Arduino nor a git repository"
    commit = head.stdout.decode().strip()
    target = CACHE / f"mecotron-{commit[:12]}"
    if not (target / ARDUINO_IN_CHECKOUT / "libraries" / "microOS").is_dir():
        archive = _git(git_dir, "archive", "--prefix=software/Arduino/", "HEAD:software/Arduino")
        if archive.returncode != 0:
            return None, f"{base}: git archive HEAD:software/Arduino failed: {archive.stderr!r}"
        partial = target.with_name(target.name + f".tmp-{os.getpid()}")
        shutil.rmtree(partial, ignore_errors=True)
        partial.mkdir(parents=True)
        subprocess.run(["tar", "-x", "-C", str(partial)], input=archive.stdout, check=True)
        shutil.rmtree(target, ignore_errors=True)
        partial.rename(target)
    return target / ARDUINO_IN_CHECKOUT, f"{base} at {commit[:12]} ({how})"


def _simavr_flags() -> list[str] | None:
    """gcc flags to build against libsimavr, or None when its headers or library are missing."""
    done = subprocess.run(
        ["pkg-config", "--cflags", "--libs", "simavr"], capture_output=True, text=True, check=False
    ) if shutil.which("pkg-config") else None  # fmt: skip
    if done is not None and done.returncode == 0:
        return done.stdout.split()
    # Debian's simavr.pc requires libelf.pc, which only libelf-dev brings; the library itself
    # links against libelf.so.1 already
    header = Path("/usr/include/simavr/sim_avr.h")
    if header.is_file():
        return ["-I", str(header.parent), "-lsimavr"]
    return None


def _missing() -> list[str]:
    missing = avr_build.missing_toolchain()
    if shutil.which("gcc") is None:
        missing.append("gcc")
    if _simavr_flags() is None:
        missing.append("simavr headers and library (Debian: libsimavr-dev)")
    return missing


MISSING = _missing()

pytestmark = [
    pytest.mark.fil,
    pytest.mark.skipif(
        bool(MISSING),
        reason=(
            f"firmware in the loop needs: {', '.join(MISSING)} "
            "(Debian: apt install gcc-avr avr-libc arduino-core-avr gcc libsimavr-dev)"
        ),
    ),
]


@pytest.fixture(autouse=True)
def _only_when_asked(request: pytest.FixtureRequest) -> None:
    """The test takes ~15 s of wall time in real time: it runs under ``-m fil`` (or
    ``CARTCTL_FIL=1``), not in the default suite."""
    if "fil" not in (request.config.getoption("-m") or "") and not os.environ.get("CARTCTL_FIL"):
        pytest.skip("firmware in the loop runs with -m fil (or CARTCTL_FIL=1)")


# -- building -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Firmware:
    elf: Path
    cached: bool
    seconds: float
    flash: int
    ram: int
    course: str
    sketch_warnings: list[str]


def _sketch_define(name: str) -> str | None:
    """The value of a ``#define name value`` in the sketch's files, as written."""
    for path in sorted(SKETCH.iterdir()):
        if path.suffix in (".h", ".cpp", ".ino"):
            found = re.search(rf"^#define\s+{name}\s+(\S+)", path.read_text(encoding="utf-8"), re.M)
            if found:
                return found.group(1)
    return None


def _build_firmware(arduino: Path, course: str) -> Firmware:
    libraries = arduino / "libraries"
    template = arduino / "CT-Student" / "mecotron.h"
    microos, components = libraries / "microOS", libraries / "components"
    sketch_files = sorted(p for p in SKETCH.iterdir() if p.is_file() and p.name != "mecotron.h")
    course_files = [
        template,
        *sorted(p for p in microos.rglob("*") if p.suffix in (".h", ".hpp", ".cpp")),
        *sorted(p for p in components.rglob("*") if p.suffix in (".h", ".cpp")),
    ]
    defines = list(SERIAL_BUFFERS)
    key = avr_build.fingerprint(
        [*avr_build.core_sources(), *avr_build.VARIANT.glob("*.h"), *course_files,
         *sketch_files, STANDBY_SOURCE],
        [*avr_build.C_FLAGS, *avr_build.CXX_FLAGS, *defines, "fil-1"],
    )  # fmt: skip
    includes = ["-I", "{sketch}", "-I", str(microos), "-I", str(components)]
    warnings: list[str] = []

    def build(folder: Path) -> Path:
        sketch = folder / "sketch"  # the sketch's files with the template's mecotron.h beside
        sketch.mkdir()
        for path in sketch_files:
            shutil.copy2(path, sketch / path.name)
        shutil.copy2(template, sketch / "mecotron.h")
        flags = [*defines, *(word.format(sketch=sketch) for word in includes)]
        course_sources = [*sorted(microos.glob("*.cpp")), *sorted(components.glob("*.cpp"))]
        course_objects = [folder / f"course_{p.parent.name}_{p.name}.o" for p in course_sources]
        ours = [*sorted(sketch.glob("*.ino")), *sorted(sketch.glob("*.cpp")), STANDBY_SOURCE]
        our_objects = [folder / f"sketch_{p.name}.o" for p in ours]
        commands = [
            *(avr_build.compile_command(s, o, [*flags, "-w"])
              for s, o in zip(course_sources, course_objects, strict=True)),
            *(avr_build.compile_command(s, o, [*flags, "-Wall", "-Wextra"])
              for s, o in zip(ours, our_objects, strict=True)),
        ]  # fmt: skip
        outputs = avr_build.parallel(commands)
        for output in outputs[len(course_sources) :]:
            warnings.extend(
                line for line in output.splitlines()
                if "warning:" in line and str(sketch) in line
                and not line.startswith(str(sketch / "mecotron.h"))
            )  # fmt: skip
        archive = avr_build.core_archive(folder, defines)
        return avr_build.link(folder / "cartctl_bridge.elf", [*course_objects, *our_objects],
                              [archive])  # fmt: skip

    start = time.perf_counter()
    elf, cached = avr_build.cached_build(BUILD_CACHE, key, build)
    seconds = time.perf_counter() - start
    flash, ram = avr_build.size(elf)
    return Firmware(elf, cached, seconds, flash, ram, course, warnings)


@pytest.fixture(scope="module")
def firmware() -> Firmware:
    arduino, course = _course_arduino()
    if arduino is None:
        pytest.skip(course)
    try:
        return _build_firmware(arduino, course)
    except avr_build.BuildError as error:
        pytest.fail(f"the bridge sketch does not build against the course's code:\n{error}",
                    pytrace=False)  # fmt: skip


@pytest.fixture(scope="module")
def harness() -> Path:
    """cart_sim, compiled with gcc against libsimavr (cached by the source's hash)."""
    flags = _simavr_flags() or []
    key = avr_build.hashlib.sha256(HARNESS_SOURCE.read_bytes() + " ".join(flags).encode())
    binary = BUILD_CACHE / f"cart_sim-{key.hexdigest()[:16]}"
    if not binary.is_file():
        BUILD_CACHE.mkdir(parents=True, exist_ok=True)
        partial = binary.with_name(binary.name + f".tmp-{os.getpid()}")
        command = ["gcc", "-O2", "-Wall", "-Wextra", "-o", str(partial), str(HARNESS_SOURCE),
                   *flags, "-lm", "-lutil"]  # fmt: skip
        try:
            avr_build.run(command)
        except avr_build.BuildError as error:
            pytest.fail(f"the harness does not build:\n{error}", pytrace=False)
        partial.rename(binary)
    return binary


# -- running ------------------------------------------------------------------------------------


class Harness:
    """cart_sim running the firmware: its pty, its output lines, and its reports."""

    def __init__(self, binary: Path, elf: Path, folder: Path, baud: int, usb: bool) -> None:
        self.report_path = folder / "cart_sim.json"
        self.log_path = folder / "cart_sim.csv"
        command = [str(binary), str(elf), "--baud", str(baud), "--report",
                   str(self.report_path), "--log", str(self.log_path), "--realtime"]  # fmt: skip
        if usb:
            command.append("--usb-latency")
        self.proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)  # fmt: skip
        assert self.proc.stdout is not None
        self.port = self.proc.stdout.readline().strip()
        if not self.port.startswith("/dev/"):
            self.proc.kill()
            _, err = self.proc.communicate()
            pytest.fail(f"cart_sim did not start: {self.port!r} {err}", pytrace=False)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.strip())

    def drive_episodes(self) -> int:
        return sum(1 for line in self.lines if line.startswith("drive "))

    def snapshot(self, timeout_s: float = 5.0) -> dict:
        """The report as it stands now (SIGUSR1), without stopping the simulation."""
        before = self.report_path.stat().st_mtime_ns if self.report_path.exists() else 0
        self.proc.send_signal(signal.SIGUSR1)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.report_path.exists() and self.report_path.stat().st_mtime_ns != before:
                with contextlib.suppress(json.JSONDecodeError):
                    return json.loads(self.report_path.read_text(encoding="utf-8"))
            time.sleep(0.02)
        pytest.fail("cart_sim wrote no report on SIGUSR1", pytrace=False)

    def stop(self) -> dict:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._reader.join(timeout=5)  # it owns stdout until the end of the stream
        assert self.proc.stdout is not None and self.proc.stderr is not None
        err = self.proc.stderr.read()
        self.proc.stdout.close()
        self.proc.stderr.close()
        if not self.report_path.exists():
            pytest.fail(f"cart_sim wrote no report: {err}", pytrace=False)
        return json.loads(self.report_path.read_text(encoding="utf-8"))


def _cartctl(*args: str) -> list[str]:
    return [sys.executable, "-m", "cartctl.cli", *args] if not shutil.which("cartctl") else [
        str(shutil.which("cartctl")), *args]  # fmt: skip


def _expected_loop_delay() -> int:
    version = _sketch_define("BRIDGE_VERSION")
    return 1 if version is not None and int(version) >= 2 else 3


def _baud() -> int:
    value = _sketch_define("BRIDGE_BAUD")
    return int(value.rstrip("UL")) if value else 115200


def test_cartctl_drives_the_real_firmware_in_real_time(
    firmware: Firmware, harness: Path, tmp_path: Path
) -> None:
    usb = os.environ.get("CARTCTL_FIL_USB", "1") != "0"
    sim = Harness(harness, firmware.elf, tmp_path, _baud(), usb)
    try:
        # 1. a normal run: cartctl's own figures
        run = subprocess.run(
            _cartctl("run", "--plant", f"serial:{sim.port}", "--json", "--rerun", "off",
                     "--out", str(tmp_path / "run"), "--duration", "3"),
            capture_output=True, text=True, timeout=60, check=False,
        )  # fmt: skip
        assert run.returncode == 0, f"cartctl run failed:\n{run.stderr}"
        summary = json.loads(run.stdout)
        after_run = sim.snapshot()

        # 2. the watchdog: a run killed while it drives sends no stop frames
        episodes = sim.drive_episodes()
        killed = subprocess.Popen(
            _cartctl("run", "--plant", f"serial:{sim.port}", "--json", "--rerun", "off",
                     "--out", str(tmp_path / "killed"), "--duration", "20"),
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 30
        while sim.drive_episodes() == episodes and time.monotonic() < deadline:
            assert killed.poll() is None, f"the second cartctl run ended: {killed.stderr}"
            time.sleep(0.05)
        assert sim.drive_episodes() > episodes, "the second cartctl run never drove the motors"
        time.sleep(0.5)
        killed.kill()
        killed.wait(timeout=10)
        assert killed.stderr is not None
        killed.stderr.close()
        time.sleep(0.5)
    finally:
        report = sim.stop()

    link = summary["link"]
    overshoot = {m: summary["motors"][m]["overshoot_percent"] for m in ("a", "b")}
    print(
        f"\nfirmware in the loop: course {firmware.course}, ELF {firmware.flash} B flash, "
        f"{firmware.ram} B RAM, build {firmware.seconds:.1f} s "
        f"({'cached' if firmware.cached else 'cold'})"
        f"\n  line {report['baud']} baud (firmware's UART {report['firmware_uart_baud']:.0f}), "
        f"USB bridge model {'on' if report['usb_latency'] else 'off'}"
        f"\n  loop delay {summary['loop_delay_ticks']} ticks (echo {link['echo_delay_ticks']}, "
        f"range {link['echo_delay_range']}), host frames lost {link['host_frames_lost']} of "
        f"{link['host_frames_sent']}, cart frames lost {link['lost_frames']}, "
        f"watchdog trips {link['watchdog_trips']}, CRC errors {link['crc_errors']}"
        f"\n  the bridge's own reports (THREAD_INFO 200..203, maxima): {link.get('cart_timing')}"
        f"\n  UART bytes dropped {report['bytes_dropped']} of {report['host_bytes_read']}"
        f"\n  after the normal run: motors at 0 V {_ms(after_run['watchdog_ms'])} after the "
        "host's last byte (its stop frames)"
        f"\n  watchdog (host killed): motors at 0 V {_ms(report['watchdog_ms'])} after the host's "
        f"last byte"
        f"\n  overshoot of the 10 rad/s step: A {overshoot['a']:.1f} %, B {overshoot['b']:.1f} %"
        f"\n  real-time factor {report['realtime_factor']:.4f} (AVR {report['avr_seconds']:.2f} s "
        f"in {report['wall_seconds']:.2f} s wall; behind the clock by up to "
        f"{report['max_lag_ms']:.1f} ms, more than 1 ms for {report['lag_over_1ms_s']:.2f} s; "
        f"SCHED_FIFO {'yes' if report['sched_fifo'] else 'no'})"
    )
    for line in firmware.sketch_warnings:
        print(f"  sketch warning: {line}")

    assert report["firmware_uart_baud"] == pytest.approx(report["baud"], rel=0.01)
    assert summary["loop_delay_ticks"] == _expected_loop_delay()
    assert report["bytes_dropped"] == 0, (
        f"the AVR's UART lost {report['bytes_dropped']} of the host's bytes to data overruns: "
        "its receive interrupt ran later than two byte times (CART_SIM_DEBUG=1 shows which "
        "interrupts ran before)"
    )
    assert link["host_frames_lost"] == 0
    # the real microOS packs the bridge's THREAD_INFO frames: cartctl's framer takes every one
    assert link["crc_errors"] == 0
    if _expected_loop_delay() == 1:
        timing = link["cart_timing"]
        assert timing is not None, "no THREAD_INFO 200..203 from the bridge"
        assert 0 < timing["tick_busy_us_max"] < 10_000
        assert 9_000 < timing["tick_interval_us_max"] < 30_000
        assert 0 < timing["rx_ring_high_water_bytes"] < 255  # the ring never filled
    assert report["watchdog_ms"] is not None, "the motors still had a voltage at the end"
    assert 0.0 < report["watchdog_ms"] <= WATCHDOG_BOUND_MS
    for motor, value in overshoot.items():
        assert value < OVERSHOOT_BOUND_PERCENT, f"motor {motor} overshoots {value:.1f} %"
    assert report["realtime_factor"] > 0.9


def _ms(value: float | None) -> str:
    return "never" if value is None else f"{value:.1f} ms"
