"""The bridge sketch built for the Arduino Mega 2560 with the AVR toolchain: flash and RAM.

The Arduino AVR core is compiled for the ATmega2560 into an archive; the sketch
(``cartctl_bridge.ino`` as C++ with ``Arduino.h`` included first, as the Arduino builder does, and
``robot.cpp``) and cartctl's stand-ins for the course headers (``tests/firmware_mock``: a
``mecotron.h`` and a ``microOS.h`` written for cartctl, not the course's code) are compiled with
``-std=gnu++11 -Wall -Wextra -Werror`` and linked with ``--gc-sections``. ``avr-size`` then gives
the flash (text + data) and the static RAM (data + bss) the image needs; heap (``String``) and
stack come on top of the RAM figure at run time. Run with ``pytest -s`` to see the figures.

A second test shows that the strict build checks the thread-function type: a copy of the sketch
whose ``update()`` returns ``void`` (the old bug, a ``void (*)()`` where microOS wants
``int (*)()``) must not compile.

Notes
-----
Needs avr-g++, avr-gcc, avr-ar, avr-size, avr-libc and the Arduino AVR core; on Debian the
packages ``gcc-avr avr-libc arduino-core-avr``. Skipped when any of them is missing. Nothing here
runs on a board, and the course's real microOS and mecotron.h are not used.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKETCH = ROOT / "firmware" / "cartctl_bridge"
MOCK = Path(__file__).resolve().parent / "firmware_mock"
ARDUINO_AVR = Path("/usr/share/arduino/hardware/arduino/avr")
CORE = ARDUINO_AVR / "cores" / "arduino"
VARIANT = ARDUINO_AVR / "variants" / "mega"

FLASH_BYTES = 256 * 1024  # ATmega2560 (the bootloader takes 8 KiB of it)
RAM_BYTES = 8 * 1024

MCU = [
    "-mmcu=atmega2560",
    "-DF_CPU=16000000L",
    "-DARDUINO=10807",
    "-DARDUINO_AVR_MEGA2560",
    "-DARDUINO_ARCH_AVR",
    "-DSERIAL_RX_BUFFER_SIZE=256",  # the bridge needs both at 500 kbaud (firmware/README.md)
    "-DSERIAL_TX_BUFFER_SIZE=256",
]
COMMON = ["-Os", "-ffunction-sections", "-fdata-sections", *MCU]
CXX_ONLY = ["-fno-exceptions", "-fno-threadsafe-statics"]  # as the Arduino builder
CORE_C = ["-std=gnu11", "-w", *COMMON, "-I", str(CORE), "-I", str(VARIANT)]
# Debian's core 1.8.7 uses float.h's DECIMAL_DIG in WString.cpp, which avr-gcc 5.4's float.h
# defines for C99 but not for C++: give it the compiler's own value.
CORE_CXX = [
    "-std=gnu++11",
    "-w",
    "-DDECIMAL_DIG=__DECIMAL_DIG__",
    *CXX_ONLY,
    *COMMON,
    "-I",
    str(CORE),
    "-I",
    str(VARIANT),
]
# The sketch and the mock: strict, no -fpermissive. The core is on -I, not -isystem: avr-gcc
# wraps C++ headers found through -isystem in an implicit extern "C", and Arduino.h's overloads
# (makeWord, random, String's operators) then fail to compile. The core's headers give no warning
# under -Wall -Wextra with avr-g++ 5.4, so every warning here is in cartctl's files or the mock.
STRICT = [
    "-std=gnu++11",
    "-Wall",
    "-Wextra",
    "-Werror",
    *CXX_ONLY,
    *COMMON,
    "-I",
    str(CORE),
    "-I",
    str(VARIANT),
    "-I",
    str(SKETCH),
    "-I",
    str(MOCK),
]


def _missing() -> list[str]:
    """What this machine lacks to build the sketch for the Mega (empty when nothing)."""
    tools = ("avr-g++", "avr-gcc", "avr-ar", "avr-size")
    missing = [tool for tool in tools if shutil.which(tool) is None]
    gcc = shutil.which("avr-gcc")
    if gcc is not None:  # avr-libc: the compiler finds the ATmega2560's libc.a
        done = subprocess.run(
            [gcc, "-mmcu=atmega2560", "-print-file-name=libc.a"],
            capture_output=True, text=True, check=False,
        )  # fmt: skip
        if not Path(done.stdout.strip()).is_absolute():
            missing.append("avr-libc")
    for folder in (CORE, VARIANT):
        if not folder.is_dir():
            missing.append(str(folder))
    return missing


MISSING = _missing()

pytestmark = pytest.mark.skipif(
    bool(MISSING),
    reason=(
        f"AVR toolchain or Arduino core missing: {', '.join(MISSING)} "
        "(Debian: apt install gcc-avr avr-libc arduino-core-avr)"
    ),
)


@dataclass(frozen=True)
class Size:
    """avr-size's Berkeley figures of a linked image, in bytes."""

    text: int
    data: int
    bss: int

    @property
    def flash(self) -> int:
        return self.text + self.data

    @property
    def ram(self) -> int:
        return self.data + self.bss


def _run(command: Sequence[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(list(command), capture_output=True, text=True, check=False)


def _check(command: Sequence[str]) -> str:
    """Runs a build step; fails the test with the command and the compiler's output."""
    done = _run(command)
    if done.returncode != 0:
        pytest.fail(f"{' '.join(command)}\n{done.stdout}{done.stderr}", pytrace=False)
    return done.stdout


def _parallel(commands: list[list[str]]) -> None:
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        list(pool.map(_check, commands))


def _strict_compile(source: Path, obj: Path) -> list[str]:
    """The sketch's compile command: a .ino as C++ with Arduino.h first, like the IDE."""
    as_cxx = ["-x", "c++", "-include", "Arduino.h"] if source.suffix == ".ino" else []
    return ["avr-g++", *STRICT, *as_cxx, "-c", str(source), "-o", str(obj)]


def _core_compile(source: Path, obj: Path) -> list[str]:
    if source.suffix == ".c":
        return ["avr-gcc", *CORE_C, "-c", str(source), "-o", str(obj)]
    return ["avr-g++", *CORE_CXX, "-c", str(source), "-o", str(obj)]


def _core_archive(build: Path) -> Path:
    """The Arduino core for the ATmega2560 (every .c and .cpp but main.cpp) as core.a."""
    sources = [*sorted(CORE.glob("*.c")), *sorted(CORE.glob("*.cpp"))]
    sources = [source for source in sources if source.name != "main.cpp"]
    objects = [build / f"{source.name}.o" for source in sources]
    _parallel([_core_compile(src, obj) for src, obj in zip(sources, objects, strict=True)])
    archive = build / "core.a"
    _check(["avr-ar", "rcs", str(archive), *map(str, objects)])
    return archive


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sketch and the mock, strict, linked with the core for the Mega: the .elf."""
    build = tmp_path_factory.mktemp("avr")
    sources = [SKETCH / "cartctl_bridge.ino", SKETCH / "robot.cpp", *sorted(MOCK.glob("*.cpp"))]
    objects = [build / f"sketch_{source.name}.o" for source in sources]
    _parallel([_strict_compile(src, obj) for src, obj in zip(sources, objects, strict=True)])
    archive = _core_archive(build)
    elf = build / "cartctl_bridge.elf"
    link = ["avr-gcc", "-Os", "-Wl,--gc-sections", *MCU, "-o", str(elf)]
    _check([*link, *map(str, objects), str(archive), "-lm"])
    return elf


def _size(elf: Path) -> Size:
    lines = _check(["avr-size", str(elf)]).splitlines()  # Berkeley: text data bss dec hex name
    text, data, bss = (int(word) for word in lines[1].split()[:3])
    return Size(text, data, bss)


def test_sketch_fits_the_atmega2560(image: Path) -> None:
    size = _size(image)
    print(
        f"\ncartctl_bridge on the ATmega2560 (mock template): "
        f"flash {size.flash} B ({100 * size.flash / FLASH_BYTES:.1f} % of 256 KiB), "
        f"RAM {size.ram} B ({100 * size.ram / RAM_BYTES:.1f} % of 8 KiB) "
        f"[text {size.text}, data {size.data}, bss {size.bss}]"
    )
    assert 0 < size.flash < FLASH_BYTES
    assert 0 < size.ram < RAM_BYTES


def test_a_void_thread_function_does_not_compile(tmp_path: Path) -> None:
    """The old bug: update() returning void is a void (*)() where addThread wants int (*)()."""
    original = (SKETCH / "cartctl_bridge.ino").read_text(encoding="utf-8")
    broken, count = re.subn(
        r"int update\(\) \{(.*?)\n  return 0;\n\}", r"void update() {\1\n}", original, flags=re.S
    )
    assert count == 1, "update() in cartctl_bridge.ino no longer looks as this test expects"
    (tmp_path / "good").mkdir()
    (tmp_path / "bad").mkdir()
    good = tmp_path / "good" / "cartctl_bridge.ino"
    bad = tmp_path / "bad" / "cartctl_bridge.ino"
    good.write_text(original, encoding="utf-8")
    bad.write_text(broken, encoding="utf-8")

    _check(_strict_compile(good, tmp_path / "good.o"))  # the same command passes on the original
    done = _run(_strict_compile(bad, tmp_path / "bad.o"))
    assert done.returncode != 0
    assert "invalid conversion" in done.stderr, done.stderr
    assert "int (*)()" in done.stderr, done.stderr
    assert "addThread" in done.stderr, done.stderr


@pytest.mark.parametrize("flag", ["-DSERIAL_RX_BUFFER_SIZE=256", "-DSERIAL_TX_BUFFER_SIZE=256"])
def test_the_sketch_needs_the_larger_serial_rings(tmp_path: Path, flag: str) -> None:
    """Built without either 256-byte ring the sketch stops with a line naming both flags."""
    command = _strict_compile(SKETCH / "cartctl_bridge.ino", tmp_path / "small.o")
    done = _run([word for word in command if word != flag])
    assert done.returncode != 0
    assert "-DSERIAL_RX_BUFFER_SIZE=256 -DSERIAL_TX_BUFFER_SIZE=256" in done.stderr, done.stderr
