"""The bridge sketch (``firmware/cartctl_bridge``) against its Python twin, tick by tick.

``bridge_logic.h`` is compiled with g++ and a harness that replays a script of ticks (some with a
GPIO frame from the host received a few ms before, each with what ``io()`` read and the time in
ms); the same script runs through
:class:`~cartctl.link.firmware.BridgeFirmware`, and every voltage and output channel
must agree. The sketch's ``robot.cpp`` is compiled too, against a mock of the template's
``MECOtron`` helpers (``readFloat``, ``writeInt``, ``setVoltageMotorA``, …), to check its glue.
Nothing here runs on a real board.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cartctl.link.bridge import SEQ_MODULO as TICK_MODULO
from cartctl.link.bridge import STATUS_DRIVING, STATUS_WATCHDOG, WATCHDOG_MS
from cartctl.link.firmware import BridgeFirmware, CartIO

ROOT = Path(__file__).resolve().parents[1]
SKETCH = ROOT / "firmware" / "cartctl_bridge"
GXX = shutil.which("g++")
CXX_FLAGS = ["-std=gnu++11", "-O2", "-Wall", "-Wextra", "-Werror", "-Wconversion"]

pytestmark = pytest.mark.skipif(GXX is None, reason="g++ is not installed")

LOGIC_HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "bridge_logic.h"

static float next_float(void) {
  char word[64];
  if (scanf("%63s", word) != 1) exit(2);
  return strtof(word, NULL);
}

/* "F ms f0..f7 i0..i3": a drain that found a frame; "T ms sa sb va vb pa pb": one control() */
int main(void) {
  BridgeState s;
  char word[16];
  unsigned long now_ms;
  bridge_reset(&s);
  while (scanf("%15s %lu", word, &now_ms) == 2) {
    if (strcmp(word, "F") == 0) {
      float floats[BRIDGE_FLOATS];
      int32_t ints[BRIDGE_INTS];
      for (int k = 0; k < BRIDGE_FLOATS; ++k) floats[k] = next_float();
      for (int k = 0; k < BRIDGE_INTS; ++k) {
        long value;
        if (scanf("%ld", &value) != 1) return 2;
        ints[k] = (int32_t)value;
      }
      bridge_receive(&s, floats, ints, (uint32_t)now_ms);
    } else {
      BridgeIO io;
      io.speed_a_rad_s = next_float();
      io.speed_b_rad_s = next_float();
      io.applied_a_v = next_float();
      io.applied_b_v = next_float();
      io.position_a_rad = next_float();
      io.position_b_rad = next_float();
      BridgeVoltages v = bridge_control(&s, &io, (uint32_t)now_ms);
      printf("%.9g %.9g", (double)v.a_v, (double)v.b_v);
      for (int k = 0; k < BRIDGE_FLOATS; ++k) printf(" %.9g", (double)s.out_floats[k]);
      for (int k = 0; k < BRIDGE_INTS; ++k) printf(" %ld", (long)s.out_ints[k]);
      printf("\n");
    }
  }
  return 0;
}
"""

# The template's helpers as the sketch uses them (names and types as in the course's mecotron.h),
# backed by plain arrays the harness fills and prints.
MOCK_MECOTRON = r"""
#ifndef MECOTRON_H
#define MECOTRON_H
#include <stdint.h>
#include <stdio.h>

#define BATTERY_VOLTAGE 12.0f
#define ON 1
#define OFF 0

struct String {
  String(const char* text) : text(text) {}
  const char* text;
};

extern float mock_gpin_float[8];
extern int32_t mock_gpin_int[4];
extern float mock_gpout_float[8];
extern int32_t mock_gpout_int[4];
extern float mock_sensor[6];  /* speed A, B, bridge voltage A, B, position A, B */
extern float mock_hbridge[2];
extern bool mock_led[2];
extern unsigned long mock_now_ms;
extern int mock_drains;
extern int mock_transmits;
extern int mock_thread_infos;

inline unsigned long millis() { return mock_now_ms; }

struct MockCommunicator {
  void receive() { mock_drains += 1; }  /* the harness has put the frame's channels in place */
  void transmit() { mock_transmits += 1; }
  void sendThreadInfo(uint8_t id, uint8_t, uint32_t duration, uint32_t, uint32_t, uint32_t,
                      uint32_t executions) {
    mock_thread_infos += 1;
    (void)id; (void)duration; (void)executions;
  }
};

struct MockSerial {
  unsigned long baud;
  void begin(unsigned long rate) { baud = rate; }
};
extern MockSerial Serial;

class MECOtron {
  MockCommunicator communicator;
  public:
    MockCommunicator* getCommunicator() { return &communicator; }
    virtual ~MECOtron() {}
    virtual bool init() { return true; }
    virtual void control() {}
    virtual void button0callback() {}
    virtual void button1callback() {}
    inline void message(String str) { printf("MSG %s\n", str.text); }
    inline void writeInt(const uint8_t nr, const int16_t val) { mock_gpout_int[nr] = val; }
    inline int16_t readInt(const uint8_t nr) { return (int16_t)mock_gpin_int[nr]; }
    inline void writeFloat(const uint8_t nr, const float val) { mock_gpout_float[nr] = val; }
    inline float readFloat(const uint8_t nr) { return mock_gpin_float[nr]; }
    inline void setVoltageMotorA(const float volts) { mock_hbridge[0] = volts; }
    inline void setVoltageMotorB(const float volts) { mock_hbridge[1] = volts; }
    inline float getVoltageMotorA() { return mock_sensor[2]; }
    inline float getVoltageMotorB() { return mock_sensor[3]; }
    inline float getPositionMotorA() { return mock_sensor[4]; }
    inline float getPositionMotorB() { return mock_sensor[5]; }
    inline float getSpeedMotorA() { return mock_sensor[0]; }
    inline float getSpeedMotorB() { return mock_sensor[1]; }
    inline void LED1(const bool on) { mock_led[0] = on; }
    inline void LED2(const bool on) { mock_led[1] = on; }
};
#endif
"""

ROBOT_HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "robot.h"

float mock_gpin_float[8];
int32_t mock_gpin_int[4];
float mock_gpout_float[8];
int32_t mock_gpout_int[4];
float mock_sensor[6];
float mock_hbridge[2];
bool mock_led[2];
unsigned long mock_now_ms;
int mock_drains;
int mock_transmits;
int mock_thread_infos;
MockSerial Serial;

static float next_float(void) {
  char word[64];
  if (scanf("%63s", word) != 1) exit(2);
  return strtof(word, NULL);
}

/* the same script as the logic harness; prints the H-bridge buffer, the GPIO out and the LEDs */
int main(void) {
  Robot robot;
  char word[16];
  robot.init();
  printf("BAUD %lu\n", Serial.baud);
  while (scanf("%15s %lu", word, &mock_now_ms) == 2) {
    if (strcmp(word, "F") == 0) {  /* microOS overwrites the held channels on receipt */
      for (int k = 0; k < 8; ++k) mock_gpin_float[k] = next_float();
      for (int k = 0; k < 4; ++k) {
        long value;
        if (scanf("%ld", &value) != 1) return 2;
        mock_gpin_int[k] = (int32_t)value;
      }
      robot.receive();
    } else {
      for (int k = 0; k < 6; ++k) mock_sensor[k] = next_float();
      robot.control();
      BridgeTiming timing = {1200, 40, 10000, 60, 0};
      robot.transmit(&timing);
      printf("%.9g %.9g", (double)mock_hbridge[0], (double)mock_hbridge[1]);
      for (int k = 0; k < 8; ++k) printf(" %.9g", (double)mock_gpout_float[k]);
      for (int k = 0; k < 4; ++k) printf(" %ld", (long)mock_gpout_int[k]);
      printf(" %d %d %d %d %d\n", (int)mock_led[0], (int)mock_led[1], mock_drains, mock_transmits,
             mock_thread_infos);
    }
  }
  return 0;
}
"""


Frame = tuple[int, tuple[float, ...], tuple[int, int, int, int]]
"""A drain that found a host frame: ms before the control(), float and int channels."""
BASE_MS = 2**32 - 2000
"""The clock of tick 0 (ms): millis() wraps 2 s into the script."""


@dataclass(frozen=True)
class Tick:
    """One control() call, after the drains (with a frame each) of the tick before it."""

    io: tuple[float, float, float, float, float, float]
    frames: tuple[Frame, ...] = ()


def _f32(value: float) -> float:
    return float(np.float32(value))


def _clock_ms(tick: int, before_ms: int = 0) -> int:
    return (BASE_MS + 10 * tick - before_ms) % 2**32


def _script(seed: int = 3) -> list[Tick]:
    """Every rule of the contract, then enough idle ticks to wrap the tick counter."""
    rng = np.random.default_rng(seed)

    def io() -> tuple[float, float, float, float, float, float]:
        sa, sb, va, vb, pa, pb = (_f32(v) for v in rng.uniform(-30.0, 30.0, 6))
        return (sa, sb, va, vb, pa, pb)

    def channels(seq: int, drive: int, va: float, vb: float, i2: int = 0, i3: int = 0) -> Frame:
        floats = (_f32(va), _f32(vb), *(_f32(v) for v in rng.uniform(-5.0, 5.0, 6)))
        return (4, floats, (seq, drive, i2, i3))

    def frame(seq: int, drive: int, va: float, vb: float, i2: int = 0, i3: int = 0) -> Tick:
        return Tick(io(), (channels(seq, drive, va, vb, i2, i3),))

    script = [Tick(io()) for _ in range(5)]  # no frame yet: 0 V, watchdog bit
    script += [frame(seq, 1, rng.uniform(-12, 12), rng.uniform(-12, 12)) for seq in range(1, 21)]
    script += [Tick(io()) for _ in range(15)]  # the host goes quiet: trips 70 ms after the last
    script += [frame(21, 0, 6.0, -6.0)]  # a new frame, but drive = 0
    script += [Tick(io()), frame(100, 2, 6.0, -6.0), Tick(io())]  # drive 2; 22..99 count as lost
    script += [frame(22, 1, math.nan, math.inf), frame(23, 1, -math.inf, 3.5)]  # not finite: 0 V
    script += [frame(24, 1, 40.0, -40.0)]  # beyond the supply: the logic passes it, robot clamps
    for seq in range(25, 45):  # a frame every other tick still drives
        script += [frame(seq, 1, 4.0, -4.0), Tick(io())]
    script += [frame(45, 1, 5.0, 5.0, i2=7, i3=-9) for _ in range(14)]  # stuck on one seq: trips
    script += [frame(32767, 1, 2.0, 2.0), frame(0, 1, 3.0, 3.0), frame(1, 1, 1.0, 1.0)]  # wraps
    script += [frame(seq, 1, 1.0, 1.0) for seq in (2, 3, 6, 7, 11)]  # 4, 5, 8, 9, 10 lost
    two = (channels(12, 1, 2.0, 2.0), channels(13, 1, 3.0, 3.0))
    script += [Tick(io(), ((7, *two[0][1:]), (2, *two[1][1:])))]  # two in one tick: none lost
    script += [Tick(io(), ((0, *channels(14, 1, 1.0, 1.0)[1:]),))]  # drained right at control()
    while len(script) < TICK_MODULO + 40:  # the tick counter wraps; a frame now and then
        n = len(script)
        script.append(frame(n % 32768, 1, 1.5, -1.5) if n % 7 == 0 else Tick(io()))
    return script


def _stdin(script: list[Tick]) -> str:
    lines = []
    for k, tick in enumerate(script):
        for before_ms, floats, ints in tick.frames:
            lines.append(
                f"F {_clock_ms(k, before_ms)} "
                + " ".join(map(repr, floats)) + " " + " ".join(map(str, ints))
            )  # fmt: skip
        lines.append(f"T {_clock_ms(k)} " + " ".join(map(repr, tick.io)))
    return "\n".join(lines) + "\n"


def _python(script: list[Tick]) -> list[tuple[float, float, list[float], list[int]]]:
    fw = BridgeFirmware()
    out = []
    for k, tick in enumerate(script):
        for before_ms, floats, ints in tick.frames:
            fw.receive(floats, ints, _clock_ms(k, before_ms))
        va, vb = fw.control(CartIO(*tick.io), _clock_ms(k))
        out.append((va, vb, list(fw.out_floats), list(fw.out_ints)))
    return out


def _compile_and_run(sources: list[Path], workdir: Path, stdin: str) -> list[str]:
    exe = workdir / "harness"
    subprocess.run(
        [GXX, *CXX_FLAGS, "-I", str(workdir), "-o", str(exe), *map(str, sources)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    done = subprocess.run([str(exe)], input=stdin, capture_output=True, text=True, check=True)
    return done.stdout.splitlines()


def _same(c_row: list[str], py: tuple[float, float, list[float], list[int]]) -> bool:
    c_floats = [np.float32(float(v)) for v in c_row[:10]]
    c_ints = [int(v) for v in c_row[10:14]]
    py_floats = [np.float32(v) for v in (py[0], py[1], *py[2])]
    return c_floats == py_floats and c_ints == py[3]


def _first_difference(rows: list[str], expected: list) -> str | None:
    assert len(rows) == len(expected)
    for k, (row, py) in enumerate(zip(rows, expected, strict=True)):
        if not _same(row.split(), py):
            return f"tick {k}: C {row} / Python {py}"
    return None


@pytest.fixture(scope="module")
def script() -> list[Tick]:
    return _script()


@pytest.fixture(scope="module")
def expected(script: list[Tick]) -> list:
    return _python(script)


def test_the_script_exercises_every_rule(script: list[Tick], expected: list) -> None:
    """The Python twin on the script does what the contract says (so the comparison means it)."""
    status = [row[3][2] for row in expected]
    volts = [(row[0], row[1]) for row in expected]
    echo = [row[3][0] for row in expected]
    lost = [row[3][3] for row in expected]
    assert status[:5] == [STATUS_WATCHDOG] * 5 and volts[:5] == [(0.0, 0.0)] * 5
    assert status[5:25] == [STATUS_DRIVING] * 20
    assert echo[5:25] == list(range(1, 21))
    first = script[5].frames[0][1]
    assert volts[5] == (first[0], first[1])  # passed through
    # the last new frame 4 ms before tick 24: at tick 30 it is 64 ms old, at tick 31 74 ms
    assert WATCHDOG_MS == 70
    assert status[25:31] == [STATUS_DRIVING] * 6
    assert status[31:40] == [STATUS_WATCHDOG] * 9 and volts[31] == (0.0, 0.0)
    assert status[40] == 0 and volts[40] == (0.0, 0.0)  # drive = 0
    assert status[42] == 0 and volts[42] == (0.0, 0.0)  # drive = 2
    assert lost[41] == 0 and lost[42] == 100 - 21 - 1  # 22..99 never arrived
    assert volts[44] == (0.0, 0.0) and volts[45] == (0.0, 3.5)  # NaN, ±inf requests
    assert lost[44] == lost[42]  # back from 100 to 22: a new host, not 32690 lost frames
    assert volts[46] == (40.0, -40.0)
    assert status[47:87] == [STATUS_DRIVING] * 40  # a frame every other tick
    assert status[87:101] == [STATUS_DRIVING] * 7 + [STATUS_WATCHDOG] * 7  # stuck on seq 45
    assert echo[101:104] == [32767, 0, 1] and status[101:104] == [STATUS_DRIVING] * 3
    assert lost[103] == lost[42]
    assert lost[104:109] == [78, 78, 80, 80, 83]  # 4, 5 and then 8, 9, 10 skipped
    assert echo[109] == 13 and lost[109] == 83  # two frames drained within one tick
    assert echo[110] == 14 and status[110] == STATUS_DRIVING  # drained right at control()
    ticks = [row[3][1] for row in expected]
    assert ticks[TICK_MODULO - 1] == TICK_MODULO - 1 and ticks[TICK_MODULO] == 0
    assert _clock_ms(0) > _clock_ms(len(script) - 1)  # the ms clock wrapped on the way


def test_bridge_logic_matches_the_python_twin_every_tick(
    script: list[Tick], expected: list, tmp_path: Path
) -> None:
    shutil.copy(SKETCH / "bridge_logic.h", tmp_path)
    (tmp_path / "harness.cpp").write_text(LOGIC_HARNESS, encoding="utf-8")
    rows = _compile_and_run([tmp_path / "harness.cpp"], tmp_path, _stdin(script))
    assert _first_difference(rows, expected) is None


def test_robot_cpp_glue_on_a_mock_template(
    script: list[Tick], expected: list, tmp_path: Path
) -> None:
    """robot.cpp reads, writes and clamps through the template's helpers as the twin says."""
    for name in ("bridge_logic.h", "robot.h", "robot.cpp"):
        shutil.copy(SKETCH / name, tmp_path)
    (tmp_path / "mecotron.h").write_text(MOCK_MECOTRON, encoding="utf-8")
    (tmp_path / "harness.cpp").write_text(ROBOT_HARNESS, encoding="utf-8")
    short = script[:200]
    lines = _compile_and_run(
        [tmp_path / "harness.cpp", tmp_path / "robot.cpp"], tmp_path, _stdin(short)
    )
    assert lines[0] == "MSG cartctl bridge ready"
    assert lines[1] == "BAUD 500000"  # the template's 115200, raised to the bridge's line rate
    rows = lines[2:]
    assert len(rows) == len(short)
    drains = 0
    for k, (row, (va, vb, floats, ints)) in enumerate(zip(rows, expected, strict=False)):
        words = row.split()
        clamped = (max(-12.0, min(12.0, va)), max(-12.0, min(12.0, vb)))
        assert _same(words[:14], (*clamped, floats, ints)), f"tick {k}: {row}"
        status = ints[2]
        drains += len(short[k].frames)  # robot.receive() drains through the communicator
        # a GPIO and four THREAD_INFO frames per tick (120 bytes after it: the USB chip passes it on)
        expected_leds = [str(int(status == STATUS_DRIVING)), str(status >> 1), str(drains),
                         str(k + 1), str(4 * (k + 1))]  # fmt: skip
        assert words[14:] == expected_leds, f"tick {k}"


def test_robot_h_says_when_mecotron_h_is_missing(tmp_path: Path) -> None:
    for name in ("bridge_logic.h", "robot.h", "robot.cpp"):
        shutil.copy(SKETCH / name, tmp_path)
    done = subprocess.run(
        [GXX, "-std=gnu++11", "-fsyntax-only", str(tmp_path / "robot.cpp")],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode != 0
    assert "mecotron.h is missing" in done.stderr
