"""cartctl's firmware says which it is (float 6), and the monitor names its channels from that.

Pure tests, no clock: the marker read from the frames the firmwares' Python twins send, the labels
checked against what each channel carries, the monitor's choice of labels on scripted frames, and
the control() code the export's header shows, compiled with g++ against the Python twin.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cartctl.design.controllerfile import load_controller
from cartctl.export.arduino import arduino_source, onboard_controllers
from cartctl.link.cart_monitor import (
    DEFAULT_LABELS,
    Monitor,
    MonitorResult,
    describe_labels,
    firmware_labels,
    parse_labels,
)
from cartctl.link.dialect import Gpio
from cartctl.link.firmware import (
    BRIDGE,
    CHANNEL_KEYS,
    ONBOARD,
    BridgeFirmware,
    CartIO,
    OnboardFirmware,
    recognise_firmware,
)
from monitor_stubs import MemoryRows, MemoryTexts, ScriptedLink

ROOT = Path(__file__).resolve().parents[1]
PI = ROOT / "controllers" / "pi.toml"
GXX = shutil.which("g++")
TRACE_COLUMNS = ("voltage_a", "voltage_b", "speed_a", "speed_b")
"""The trace columns besides time_s (docs/architecture.md, "Trace columns")."""
IO = CartIO(1.5, -2.25, 3.0, -4.5, 6.0, -7.5)
"""A tick's io() with a distinct value in every field."""


class _Hold:
    """A controller stub: u = 0.5 (r − y)."""

    def reset(self) -> None:
        pass

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float:
        return 0.5 * (reference_rad_s - measured_rad_s)


def _bridge_frame() -> tuple[list[float], list[int]]:
    firmware = BridgeFirmware()
    firmware.control(IO, 0)
    return list(firmware.out_floats), list(firmware.out_ints)


def _onboard_frame() -> tuple[list[float], list[int]]:
    firmware = OnboardFirmware({"a": _Hold(), "b": _Hold()}, reference="const:10")
    firmware.control(IO, 0)
    return list(firmware.out_floats), list(firmware.out_ints)


def _with_marker(value: float) -> tuple[list[float], list[int]]:
    floats, ints = _onboard_frame()
    floats[6] = value
    return floats, ints


# -- recognition --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("frame", "expected"),
    [
        (_bridge_frame(), BRIDGE),
        (_onboard_frame(), ONBOARD),
        (_with_marker(0.0), None),  # the course's own code, a bridge before version 2
        (_with_marker(1.0), None),  # a bridge version whose channel map is not known
        (_with_marker(1002.0), None),  # an on-board layout that is not known
        (_with_marker(float(np.nextafter(np.float32(1001.0), np.float32(2000.0)))), None),
        (_with_marker(math.nan), None),
        (_with_marker(-1001.0), None),
    ],
)
def test_the_marker_in_float_6_tells_the_firmware(
    frame: tuple[list[float], list[int]], expected: object
) -> None:
    assert recognise_firmware(*frame) is expected


def test_a_frame_of_the_wrong_size_is_refused() -> None:
    with pytest.raises(ValueError, match="8 floats and 4 ints"):
        recognise_firmware([0.0] * 7, [0] * 4)


def _labelled(firmware: object, frame: tuple[list[float], list[int]]) -> dict[str, float]:
    labels = firmware_labels(firmware)  # type: ignore[arg-type]
    return dict(zip(labels, [*frame[0], *frame[1]], strict=True))


def test_bridge_labels_name_what_each_channel_carries() -> None:
    channel = _labelled(BRIDGE, _bridge_frame())
    assert (channel["speed_a"], channel["speed_b"]) == (IO.speed_a_rad_s, IO.speed_b_rad_s)
    assert (channel["voltage_a"], channel["voltage_b"]) == (IO.applied_a_v, IO.applied_b_v)
    assert (channel["position_a_rad"], channel["position_b_rad"]) == (6.0, -7.5)
    assert channel["bridge_version"] == 2.0
    assert channel["cart_tick"] == 0 and channel["status"] == 2  # tick 0, watchdog tripped


def test_onboard_labels_name_what_each_channel_carries() -> None:
    channel = _labelled(ONBOARD, _onboard_frame())
    assert (channel["speed_a"], channel["speed_b"]) == (1.5, -2.25)
    assert (channel["reference_a"], channel["reference_b"]) == (10.0, 10.0)
    # u = 0.5 (r − y) of the stub, by hand
    assert (channel["voltage_a"], channel["voltage_b"]) == (4.25, 6.125)
    assert channel["firmware_id"] == 1001.0


@pytest.mark.parametrize("firmware", [BRIDGE, ONBOARD], ids=["bridge", "onboard"])
def test_firmware_labels_are_trace_columns_and_valid_labels(firmware: object) -> None:
    labels = firmware_labels(firmware)  # type: ignore[arg-type]
    assert set(TRACE_COLUMNS) <= set(labels)
    # the same labels pass the --labels checks (identifiers, unique, not time_s or tick)
    text = ",".join(f"{k}={v}" for k, v in zip(CHANNEL_KEYS, labels, strict=True))
    assert parse_labels(text) == labels
    # the channels a firmware does not name keep QRoboticsCenter's label
    named = dict(firmware.labels)  # type: ignore[attr-defined]
    for key, label, default in zip(CHANNEL_KEYS, labels, DEFAULT_LABELS, strict=True):
        assert label == named.get(key, default)


def test_unknown_firmware_keeps_qrc_labels() -> None:
    assert firmware_labels(None) == DEFAULT_LABELS


# -- the monitor's choice, on scripted frames ---------------------------------------------------


def _gpio(k: int, marker: float) -> Gpio:
    floats = [float(k), 0.0, 0.0, 0.0, 0.0, 0.0, marker, 0.0]
    return Gpio(10 * k, tuple(floats), (0, 0, 0, 0))


def _run(
    script: list[object], labels: tuple[str, ...] | None = None
) -> tuple[Monitor, MemoryRows, MemoryTexts, list[str], MonitorResult]:
    rows, texts, said = MemoryRows(), MemoryTexts(), list[str]()
    monitor = Monitor([rows], [texts], labels, announce=said.append)
    result = monitor.run(ScriptedLink(monitor, script))  # type: ignore[arg-type]
    return monitor, rows, texts, said, result


def test_marker_after_a_few_unmarked_frames_names_every_row() -> None:
    """A firmware's first frames may leave before its control() wrote them: nothing is lost."""
    script: list[object] = ["boot", _gpio(0, 0.0), _gpio(1, 0.0), "hello", _gpio(2, 1001.0),
                            _gpio(3, 1001.0)]  # fmt: skip
    monitor, rows, texts, said, result = _run(script)
    assert monitor.firmware is ONBOARD
    assert rows.columns is not None and rows.columns[2:9] == [
        "speed_a", "speed_b", "voltage_a", "voltage_b", "reference_a", "reference_b",
        "firmware_id"]  # fmt: skip
    table = np.array(rows.rows)
    np.testing.assert_allclose(table[:, 0], [0.0, 0.01, 0.02, 0.03])
    np.testing.assert_array_equal(table[:, 2], [0, 1, 2, 3])  # every frame, in order
    assert [t[1:] for t in texts.texts] == [("boot", 0.0, 0), ("hello", 0.01, 1)]  # as they came
    assert result.frames == 4 and result.stopped == "fault"
    assert len(said) == 1 and "on-board controller" in said[0] and "float 6 = 1001" in said[0]


def test_no_marker_in_the_first_frames_keeps_qrc_labels() -> None:
    script: list[object] = [_gpio(k, 0.0) for k in range(10)] + [_gpio(10, 1001.0)]
    monitor, rows, _, said, result = _run(script)
    assert monitor.firmware is None and rows.columns == ["time_s", "tick", *DEFAULT_LABELS]
    assert result.frames == 11
    assert said == [
        "firmware: not one of cartctl's, by float 6 = 0; QRoboticsCenter's labels "
        "(FloatIn0..7, IntIn0..3); name the channels with --labels"
    ]


def test_a_short_run_without_marker_writes_its_frames() -> None:
    _, rows, _, said, result = _run([_gpio(0, 0.5), _gpio(1, 0.5)])
    assert rows.columns == ["time_s", "tick", *DEFAULT_LABELS] and len(rows.rows) == 2
    assert "float 6 = 0.5" in said[0] and result.stopped == "fault"


def test_no_frame_still_opens_the_sinks() -> None:
    _, rows, _, said, _ = _run(["only text"])
    assert rows.columns == ["time_s", "tick", *DEFAULT_LABELS] and rows.rows == []
    assert said == [describe_labels(None, None, DEFAULT_LABELS, given=False)]
    assert "no frame came" in said[0]
    # no frame, so no word on the firmware (it said "not one of cartctl's, by no frame came")
    assert said[0].startswith("firmware: unknown, no frame came; ") and "cartctl's" not in said[0]


def test_given_labels_override_and_the_firmware_is_still_told() -> None:
    given = parse_labels("f0=left,f6=marker")
    monitor, rows, _, said, _ = _run([_gpio(0, 2.0), _gpio(1, 2.0)], given)
    assert monitor.firmware is BRIDGE
    assert rows.columns == ["time_s", "tick", *given]
    assert said == [
        "firmware: cartctl bridge version 2, by float 6 = 2; labels from --labels "
        "f0=left,f6=marker, the others QRoboticsCenter's"
    ]


# -- the export's control() code, compiled, against its Python twin ------------------------------

MOCK_ROBOT = r"""
#include <stdio.h>
#include <stdlib.h>
#include "cartctl_controller.h"

static float gpin[8], gpout[8], sensor[2], hbridge[2];

struct Robot {
  float readFloat(int nr) { return gpin[nr]; }
  void writeFloat(int nr, float value) { gpout[nr] = value; }
  float getSpeedMotorA() { return sensor[0]; }
  float getSpeedMotorB() { return sensor[1]; }
  void setVoltageMotorA(float v) { hbridge[0] = v; }
  void setVoltageMotorB(float v) { hbridge[1] = v; }
  bool controlEnabled() { return true; }
  void control();
};

CONTROL_BODY

/* each line: "r_a r_b y_a y_b"; prints the 8 out floats after control() */
int main(void) {
  Robot robot;
  while (scanf("%f %f %f %f", &gpin[0], &gpin[1], &sensor[0], &sensor[1]) == 4) {
    robot.control();
    for (int k = 0; k < 8; ++k) printf("%.9g ", (double)gpout[k]);
    printf("\n");
  }
  return 0;
}
"""


def _control_body(source: str) -> str:
    """The ``Robot::control()`` the header's comment shows, as code."""
    match = re.search(r"^//   void Robot::control\(\) \{\n(.*?)^//   \}\n", source, re.S | re.M)
    assert match is not None, "the header shows control()"
    lines = ["void Robot::control() {", *(line[4:] for line in match.group(1).splitlines()), "}"]
    return "\n".join(lines)


@pytest.mark.skipif(GXX is None, reason="g++ is not installed")
def test_exported_control_sends_the_marker_and_the_layout_of_its_twin(tmp_path: Path) -> None:
    source = arduino_source(load_controller(PI))
    (tmp_path / "cartctl_controller.h").write_text(source, encoding="utf-8")
    (tmp_path / "robot.cpp").write_text(
        MOCK_ROBOT.replace("CONTROL_BODY", _control_body(source)), encoding="utf-8"
    )
    binary = tmp_path / "robot"
    subprocess.run([GXX, "-std=gnu++11", "-Wall", "-Wextra", "-Werror", "-o", str(binary),
                    str(tmp_path / "robot.cpp")], check=True, capture_output=True)  # fmt: skip
    rng = np.random.default_rng(23)
    ticks = np.float32(rng.uniform(-12.0, 12.0, (40, 4)))  # r_a r_b y_a y_b
    ticks[:10, :2] = 8.0
    text = "\n".join(" ".join(repr(float(v)) for v in row) for row in ticks) + "\n"
    done = subprocess.run([str(binary)], input=text, capture_output=True, text=True, check=True)
    c_out = np.array([[float(v) for v in line.split()] for line in done.stdout.splitlines()])
    twin = OnboardFirmware(onboard_controllers(PI))  # reads the held references, as the C
    for k, (r_a, r_b, y_a, y_b) in enumerate(ticks):
        twin.receive([float(r_a), float(r_b), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0] * 4)
        twin.control(CartIO(float(y_a), float(y_b), 0.0, 0.0, 0.0, 0.0))
        np.testing.assert_allclose(c_out[k], twin.out_floats, rtol=1e-4, atol=1e-3)
        assert recognise_firmware(list(c_out[k]), [0] * 4) is ONBOARD
    named = _labelled(ONBOARD, (list(c_out[-1]), [0] * 4))
    assert np.float32(named["reference_a"]) == ticks[-1, 0]  # %.9g: the float32 itself
    assert np.float32(named["speed_b"]) == ticks[-1, 3]
