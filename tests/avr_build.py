"""Building Arduino sketches for the ATmega2560 with Debian's AVR toolchain, for the tests.

The helpers here compile the Arduino AVR core into an archive and C/C++ sources into objects with
the flags the Arduino builder uses for the Mega 2560, in parallel, and link an ELF. They hold no
course code: the firmware-in-the-loop test (``tests/test_firmware_fil.py``) points them at the
course's sources on this machine, outside the repository.

``cached_build`` keeps a build in a folder named by a hash of everything that goes into it (the
compiler's version, the flags, the content of every source and header), so a second run with the
same inputs reuses the ELF.

Needs avr-g++, avr-gcc, avr-ar, avr-size, avr-libc and the Arduino AVR core; on Debian the
packages ``gcc-avr avr-libc arduino-core-avr``. :func:`missing_toolchain` names what is absent.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ARDUINO_AVR = Path("/usr/share/arduino/hardware/arduino/avr")
CORE = ARDUINO_AVR / "cores" / "arduino"
VARIANT = ARDUINO_AVR / "variants" / "mega"

MCU = [
    "-mmcu=atmega2560",
    "-DF_CPU=16000000L",
    "-DARDUINO=10807",
    "-DARDUINO_AVR_MEGA2560",
    "-DARDUINO_ARCH_AVR",
]
COMMON = ["-Os", "-ffunction-sections", "-fdata-sections", *MCU]
CXX_ONLY = ["-fno-exceptions", "-fno-threadsafe-statics"]  # as the Arduino builder
CORE_INCLUDES = ["-I", str(CORE), "-I", str(VARIANT)]
# Debian's core 1.8.7 uses float.h's DECIMAL_DIG in WString.cpp, which avr-gcc 5.4's float.h
# defines for C99 but not for C++: give it the compiler's own value. Headers go on -I, never
# -isystem: avr-gcc wraps C++ headers found through -isystem in an implicit extern "C".
C_FLAGS = ["-std=gnu11", *COMMON, *CORE_INCLUDES]
CXX_FLAGS = ["-std=gnu++11", "-DDECIMAL_DIG=__DECIMAL_DIG__", *CXX_ONLY, *COMMON, *CORE_INCLUDES]


class BuildError(RuntimeError):
    """A build step failed; the message holds the command and the compiler's output."""


def missing_toolchain() -> list[str]:
    """What this machine lacks to build for the Mega (empty when nothing)."""
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


def run(command: Sequence[str]) -> str:
    """Runs a build step and returns its stdout + stderr; raises BuildError when it fails."""
    done = subprocess.run(list(command), capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise BuildError(f"{' '.join(command)}\n{done.stdout}{done.stderr}")
    return done.stdout + done.stderr


def parallel(commands: Iterable[Sequence[str]]) -> list[str]:
    """Runs independent build steps on every core; their outputs, in order."""
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        return list(pool.map(run, commands))


def compile_command(source: Path, obj: Path, flags: Sequence[str]) -> list[str]:
    """avr-gcc for .c, avr-g++ for the rest; a .ino is C++ with Arduino.h first, like the IDE."""
    if source.suffix == ".c":
        return ["avr-gcc", *C_FLAGS, *flags, "-c", str(source), "-o", str(obj)]
    as_cxx = ["-x", "c++", "-include", "Arduino.h"] if source.suffix == ".ino" else []
    return ["avr-g++", *CXX_FLAGS, *flags, *as_cxx, "-c", str(source), "-o", str(obj)]


def core_sources() -> list[Path]:
    """The Arduino core's sources but main.cpp (a sketch brings its own main())."""
    sources = [*sorted(CORE.glob("*.c")), *sorted(CORE.glob("*.cpp"))]
    return [source for source in sources if source.name != "main.cpp"]


def core_archive(build: Path, defines: Sequence[str] = ()) -> Path:
    """The Arduino core for the ATmega2560 as ``build/core.a``, with extra -D flags."""
    sources = core_sources()
    objects = [build / f"core_{source.name}.o" for source in sources]
    parallel(
        compile_command(src, obj, ["-w", *defines])
        for src, obj in zip(sources, objects, strict=True)
    )
    archive = build / "core.a"
    run(["avr-ar", "rcs", str(archive), *map(str, objects)])
    return archive


def link(elf: Path, objects: Sequence[Path], archives: Sequence[Path] = ()) -> Path:
    """Links objects and archives for the ATmega2560 with --gc-sections, as the IDE does."""
    command = ["avr-gcc", "-Os", "-Wl,--gc-sections", *MCU, "-o", str(elf)]
    run([*command, *map(str, objects), *map(str, archives), "-lm"])
    return elf


def size(elf: Path) -> tuple[int, int]:
    """(flash, static RAM) in bytes: avr-size's text + data and data + bss."""
    lines = run(["avr-size", str(elf)]).splitlines()  # Berkeley: text data bss dec hex name
    text, data, bss = (int(word) for word in lines[1].split()[:3])
    return text + data, data + bss


def fingerprint(files: Iterable[Path], extra: Iterable[str] = ()) -> str:
    """A hash of the compiler's version, ``extra`` (flags, names) and the files' names + content."""
    digest = hashlib.sha256()
    for tool in ("avr-gcc", "avr-g++"):
        digest.update(run([tool, "--version"]).encode())
    for word in extra:
        digest.update(word.encode() + b"\0")
    for path in sorted(files, key=str):
        digest.update(str(path).encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()[:20]


def cached_build(cache: Path, key: str, build: Callable[[Path], Path]) -> tuple[Path, bool]:
    """``build(folder)`` into ``cache/key`` unless a finished build is there; (ELF, was cached).

    ``build`` returns the ELF it linked. A build that fails leaves nothing behind; a finished one
    is renamed into place in one step, so a build interrupted half-way is never taken for one.
    """
    done = cache / key
    marker = done / "elf-name"
    if marker.is_file():
        elf = done / marker.read_text(encoding="utf-8").strip()
        if elf.is_file():
            return elf, True
    cache.mkdir(parents=True, exist_ok=True)
    work = cache / f"{key}.tmp-{os.getpid()}"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    try:
        elf = build(work)
        (work / "elf-name").write_text(elf.relative_to(work).as_posix(), encoding="utf-8")
        shutil.rmtree(done, ignore_errors=True)
        work.rename(done)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return done / elf.relative_to(work), False
