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

import re
from pathlib import Path

import pytest

from avr_build import (
    BuildError,
    compile_command,
    core_archive,
    link,
    missing_toolchain,
    parallel,
    run,
    size,
)

ROOT = Path(__file__).resolve().parents[1]
SKETCH = ROOT / "firmware" / "cartctl_bridge"
MOCK = Path(__file__).resolve().parent / "firmware_mock"

FLASH_BYTES = 256 * 1024  # ATmega2560 (the bootloader takes 8 KiB of it)
RAM_BYTES = 8 * 1024

SERIAL_RINGS = ["-DSERIAL_RX_BUFFER_SIZE=256", "-DSERIAL_TX_BUFFER_SIZE=256"]
"""The bridge needs both at 500 kbaud (firmware/README.md); the core is built with them too."""
# The sketch and the mock: strict, no -fpermissive. The core's headers give no warning under
# -Wall -Wextra with avr-g++ 5.4, so every warning here is in cartctl's files or the mock.
STRICT = ["-Wall", "-Wextra", "-Werror", *SERIAL_RINGS, "-I", str(SKETCH), "-I", str(MOCK)]

MISSING = missing_toolchain()

pytestmark = pytest.mark.skipif(
    bool(MISSING),
    reason=(
        f"AVR toolchain or Arduino core missing: {', '.join(MISSING)} "
        "(Debian: apt install gcc-avr avr-libc arduino-core-avr)"
    ),
)


def _strict_compile(source: Path, obj: Path) -> list[str]:
    """The sketch's compile command: a .ino as C++ with Arduino.h first, like the IDE."""
    return compile_command(source, obj, STRICT)


def _check(command: list[str]) -> str:
    """Runs a build step; fails the test with the command and the compiler's output."""
    try:
        return run(command)
    except BuildError as exc:
        pytest.fail(str(exc), pytrace=False)


def _fails(command: list[str]) -> str:
    """Runs a build step that must fail; returns the compiler's output."""
    try:
        run(command)
    except BuildError as exc:
        return str(exc)
    pytest.fail(f"{' '.join(command)} built, but it must not", pytrace=False)


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sketch and the mock, strict, linked with the core for the Mega: the .elf."""
    build = tmp_path_factory.mktemp("avr")
    sources = [SKETCH / "cartctl_bridge.ino", SKETCH / "robot.cpp", *sorted(MOCK.glob("*.cpp"))]
    objects = [build / f"sketch_{source.name}.o" for source in sources]
    try:
        parallel(_strict_compile(src, obj) for src, obj in zip(sources, objects, strict=True))
        return link(build / "cartctl_bridge.elf", objects, [core_archive(build, SERIAL_RINGS)])
    except BuildError as exc:
        pytest.fail(str(exc), pytrace=False)


def test_sketch_fits_the_atmega2560(image: Path) -> None:
    flash, ram = size(image)
    print(
        f"\ncartctl_bridge on the ATmega2560 (mock template): "
        f"flash {flash} B ({100 * flash / FLASH_BYTES:.1f} % of 256 KiB), "
        f"RAM {ram} B ({100 * ram / RAM_BYTES:.1f} % of 8 KiB)"
    )
    assert 0 < flash < FLASH_BYTES
    assert 0 < ram < RAM_BYTES


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
    output = _fails(_strict_compile(bad, tmp_path / "bad.o"))
    assert "invalid conversion" in output, output
    assert "int (*)()" in output, output
    assert "addThread" in output, output


@pytest.mark.parametrize("flag", ["-DSERIAL_RX_BUFFER_SIZE=256", "-DSERIAL_TX_BUFFER_SIZE=256"])
def test_the_sketch_needs_the_larger_serial_rings(tmp_path: Path, flag: str) -> None:
    """Built without either 256-byte ring the sketch stops with a line naming both flags."""
    command = _strict_compile(SKETCH / "cartctl_bridge.ino", tmp_path / "small.o")
    output = _fails([word for word in command if word != flag])
    assert "-DSERIAL_RX_BUFFER_SIZE=256 -DSERIAL_TX_BUFFER_SIZE=256" in output, output
