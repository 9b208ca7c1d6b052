"""``cartctl monitor`` and the on-board controller of the virtual cart.

Unit tests (labels, the monitor's row loop on a scripted link, the on-board firmware's channels)
run without a clock. A few short integration tests run the virtual cart in real time behind a real
pseudo-terminal (marked ``realtime``; they check what happens, never how fast): the on-board PI
tracking a step, a pulled cable, a silent port and Ctrl-C.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.design.controllerfile import load_controller
from cartctl.errors import InputError
from cartctl.export.arduino import onboard_controllers
from cartctl.link.cart_monitor import (
    CHANNEL_KEYS,
    DEFAULT_LABELS,
    EVENT_ENTITY,
    PRINT_ENTITY,
    Monitor,
    parse_labels,
)
from cartctl.link.dialect import Event, Gpio
from cartctl.link.firmware import CartIO, OnboardFirmware
from monitor_stubs import MemoryRows, MemoryTexts, ScriptedLink

ROOT = Path(__file__).resolve().parents[1]
PI = ROOT / "controllers" / "pi.toml"


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("cartctl")]


def _read_csv(path: str | Path) -> tuple[list[str], np.ndarray]:
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    assert all(len(r) == len(rows[0]) for r in rows), "every row complete"
    return rows[0], np.array(rows[1:], dtype=float).reshape(-1, len(rows[0]))


# -- labels ------------------------------------------------------------------------------------


def test_default_labels_are_qrcs() -> None:
    assert parse_labels(None) == DEFAULT_LABELS
    assert DEFAULT_LABELS[0] == "FloatIn0" and DEFAULT_LABELS[-1] == "IntIn3"
    assert len(CHANNEL_KEYS) == len(DEFAULT_LABELS) == 12


def test_user_labels_replace_defaults() -> None:
    labels = parse_labels(" f0=speed_a, F1=speed_b,i0=echo,")
    assert labels[:3] == ("speed_a", "speed_b", "FloatIn2")
    assert labels[8] == "echo" and labels[9] == "IntIn1"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("x0=a", "expected KEY=LABEL"),
        ("f8=a", "expected KEY=LABEL"),
        ("i4=a", "expected KEY=LABEL"),
        ("speed_a", "expected KEY=LABEL"),
        ("f0=a,f0=b", "labelled twice"),
        ("f0=1speed", "must be an identifier"),
        ("f0=speed-a", "must be an identifier"),
        ("f0=", "must be an identifier"),
        ("f0=a b", "must be an identifier"),
        ("f0=speed,f1=speed", "already used by channel f0"),
        ("f0=FloatIn1", "already used"),
        ("i2=time_s", "the time column"),
        ("f3=tick", "the tick column"),
    ],
)
def test_bad_labels(text: str, match: str) -> None:
    with pytest.raises(InputError, match=match):
        parse_labels(text)


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["virtual", "--labels", "q1=a"], "bad label 'q1=a'"),
        (["virtual", "--reference", "step:8"], "--reference needs --onboard"),
        (["serial:/dev/x", "--onboard", str(PI)], "virtual cart"),
        (["usb:/dev/x"], "unknown plant"),
        (["serial:"], "needs a port"),
        (["virtual", "--duration", "0"], "--duration"),
        (["virtual", "--connect-timeout", "nan"], "--connect-timeout"),
        (["virtual:bogus=1"], "bad virtual cart option 'bogus=1'"),
        (["virtual", "--onboard", "missing.toml"], "not found"),
    ],
)
def test_user_mistakes_are_one_line(
    argv: list[str], match: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, out, err = _cli(capsys, "monitor", *argv, "--out", str(tmp_path))
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and match in err
    assert not list(tmp_path.iterdir()), "no file for a mistake"


# -- the monitor loop on a scripted link --------------------------------------------------------


def _gpio(time_ms: int, value: float) -> Gpio:
    return Gpio(time_ms, (value, -value, 0.1, 0, 0, 0, 0, 0), (7, -3, 0, 2**31 - 1))


def _monitor() -> tuple[Monitor, MemoryRows, MemoryTexts]:
    rows, texts = MemoryRows(), MemoryTexts()
    monitor = Monitor([rows], [texts], parse_labels("f0=speed_a,i1=status"))
    monitor.open()
    return monitor, rows, texts


def test_rows_texts_and_fault() -> None:
    monitor, rows, texts = _monitor()
    script = ["hello", _gpio(5000, 1.0), _gpio(5010, 2.0), Event(1003), "line",
              _gpio(5030, 3.0), Event(42)]  # fmt: skip
    result = monitor.run(ScriptedLink(monitor, script))  # type: ignore[arg-type]
    assert rows.columns[:4] == ["time_s", "tick", "speed_a", "FloatIn1"]
    assert rows.columns[-3:] == ["status", "IntIn2", "IntIn3"]
    table = np.array(rows.rows)
    np.testing.assert_allclose(table[:, 0], [0.0, 0.01, 0.03])  # cart time since the first GPIO
    np.testing.assert_array_equal(table[:, 1], [0, 1, 2])
    np.testing.assert_array_equal(table[:, 2], [1.0, 2.0, 3.0])
    assert table[0, 4] == np.float32(0.1)  # float32 on the wire
    np.testing.assert_array_equal(table[0, 10:], [7, -3, 0, 2**31 - 1])
    assert texts.texts == [
        (PRINT_ENTITY, "hello", 0.0, 0),  # before the first GPIO
        (EVENT_ENTITY, "button 3 pressed", 0.01, 1),  # stamped with the last GPIO
        (PRINT_ENTITY, "line", 0.01, 1),
        (EVENT_ENTITY, "event 42", 0.03, 2),
    ]
    assert (result.frames, result.print_lines, result.events) == (3, 2, 2)
    assert result.stopped == "fault" and "no data" in (result.failure or "")
    assert result.duration_s == pytest.approx(0.03)


def test_duration_is_cart_time_and_time_wraps() -> None:
    monitor, rows, _ = _monitor()
    start = 2**32 - 20  # the u32 millisecond counter wraps within the run
    script = [_gpio((start + 10 * k) % 2**32, k) for k in range(10)]
    result = monitor.run(ScriptedLink(monitor, script), duration_s=0.05)  # type: ignore[arg-type]
    assert result.stopped == "duration" and result.failure is None
    np.testing.assert_allclose(np.array(rows.rows)[:, 0], [0.0, 0.01, 0.02, 0.03, 0.04])


def test_stop_request_ends_cleanly() -> None:
    monitor, rows, _ = _monitor()
    monitor.stop_requested = True
    result = monitor.run(ScriptedLink(monitor, [_gpio(0, 1.0)]))  # type: ignore[arg-type]
    assert result.stopped == "interrupted" and rows.rows == []


# -- the on-board firmware ---------------------------------------------------------------------


class _Proportional:
    """A controller stub: u = k (r − y), clamped."""

    voltage_limit_v = 12.0
    estimate_rad_s = 0.0

    def __init__(self, k: float) -> None:
        self.k = k

    def reset(self) -> None:
        pass

    def step(self, reference_rad_s: float, measured_rad_s: float) -> float:
        self.estimate_rad_s = measured_rad_s
        return max(-12.0, min(12.0, self.k * (reference_rad_s - measured_rad_s)))


def _io(speed_a: float, speed_b: float) -> CartIO:
    return CartIO(speed_a, speed_b, 0.0, 0.0, 0.0, 0.0)


def test_onboard_channels_follow_the_export_layout() -> None:
    firmware = OnboardFirmware({"a": _Proportional(1.0), "b": _Proportional(2.0)},
                               reference="step:5:0.02")  # fmt: skip
    assert firmware.control(_io(1.0, 0.5)) == (-1.0, -1.0)  # reference 0 before 0.02 s
    firmware.control(_io(0.0, 0.0))
    voltages = firmware.control(_io(1.0, 0.5))
    assert voltages == (4.0, 9.0)
    assert firmware.out_floats == [1.0, 0.5, 4.0, 9.0, 5.0, 5.0, 1001.0, 0.0]  # 6: the marker
    assert firmware.out_ints == [0, 0, 0, 0]


def test_onboard_reads_held_channels_without_a_spec() -> None:
    firmware = OnboardFirmware({"a": _Proportional(1.0)})
    firmware.receive([3.0, 4.0, 0, 0, 0, 0, 0, 0], [0, 0, 0, 0])
    assert firmware.control(_io(1.0, 1.0)) == (2.0, 0.0)  # no controller for b: 0 V
    assert firmware.control(_io(2.0, 1.0)) == (1.0, 0.0)  # held until the next GPIO
    assert firmware.out_floats[:6] == [2.0, 0.0, 1.0, 0.0, 3.0, 0.0]


def test_onboard_reference_beyond_the_first_block() -> None:
    firmware = OnboardFirmware({"a": _Proportional(1.0)}, reference="ramp:1")
    firmware.tick = 7000  # past the precomputed 60 s
    assert firmware.reference_at("a") == pytest.approx(70.0)


def test_onboard_from_file(tmp_path: Path) -> None:
    firmware = OnboardFirmware(onboard_controllers(PI), reference="const:8")
    assert set(firmware.controllers) == {"a", "b"}
    assert firmware.control(_io(0.0, 0.0))[0] > 0.0
    slow = tmp_path / "slow.toml"  # a consistent 20 ms file: C(z) = Kp + Ki·Ts·z/(z−1) at 0.02 s
    text = PI.read_text().replace("period_s = 0.01", "period_s = 0.02")
    for entry in load_controller(PI).motors.values():
        old = f"    {entry['kp'] + entry['ki'] * 0.01!r},\n    {-entry['kp']!r},"
        assert old in text
        text = text.replace(
            old, f"    {entry['kp'] + entry['ki'] * 0.02!r},\n    {-entry['kp']!r},"
        )
    slow.write_text(text)
    with pytest.raises(InputError, match=r"every 0\.01 s"):
        onboard_controllers(slow)
    with pytest.raises(InputError, match="unknown reference"):
        OnboardFirmware(onboard_controllers(PI), reference="sine:3")


# -- real time, through the pseudo-terminal ------------------------------------------------------


@pytest.mark.realtime
def test_monitor_onboard_pi(capsys: pytest.CaptureFixture[str], tmp_path: Path, rrd_rows) -> None:
    labels = "f0=speed_a,f1=speed_b,f2=voltage_a,f3=voltage_b,f4=reference_a,f5=reference_b"
    code, out, err = _cli(capsys, "monitor", "virtual", "--onboard", str(PI), "--reference",
                          "step:8", "--duration", "1.5", "--labels", labels, "--rerun", "save",
                          "--out", str(tmp_path), "--name", "m", "--json")  # fmt: skip
    assert code == 0, err
    summary = json.loads(out)
    assert summary["stopped"] == "duration" and summary["failure"] is None
    assert 140 <= summary["frames"] <= 152
    assert summary["link"]["crc_errors"] == 0
    assert summary["trace"] == str(tmp_path / "m.csv")
    header, table = _read_csv(summary["trace"])
    assert header[:8] == ["time_s", "tick", "speed_a", "speed_b", "voltage_a", "voltage_b",
                          "reference_a", "reference_b"]  # fmt: skip
    assert header[8:] == ["FloatIn6", "FloatIn7", "IntIn0", "IntIn1", "IntIn2", "IntIn3"]
    assert len(table) == summary["frames"]
    np.testing.assert_array_equal(table[:, 1], np.arange(len(table)))
    assert np.all(np.diff(table[:, 0]) >= 0) and table[-1, 0] < 1.5  # a late cart tick catches up
    late = table[:, 0] > 1.0
    assert np.all(table[late, 6:8] == 8.0)
    assert np.abs(table[late, 2:4].mean(axis=0) - 8.0).max() < 0.5  # speeds reach 8 rad/s
    assert np.all(np.abs(table[:, 4:6]) <= 12.0)
    entities = rrd_rows(summary["recording"])
    for label in (*header[2:],):
        assert entities[f"gpio/{label}"] == len(table)
    assert entities.get("cart/print") == 1  # the cart's boot line


@pytest.mark.realtime
def test_pulled_cable_is_one_error_and_valid_files(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, rrd_rows
) -> None:
    code, out, err = _cli(capsys, "monitor", "virtual:pull=0.5", "--duration", "5", "--rerun",
                          "save", "--out", str(tmp_path), "--name", "f", "--json")  # fmt: skip
    assert code == 1
    errors = _error_lines(err)
    assert len(errors) == 1 and ("vanished" in errors[0] or "no data" in errors[0])
    summary = json.loads(out)
    assert summary["stopped"] == "fault"
    _, table = _read_csv(tmp_path / "f.csv")
    # frames until the cable went (0.5 s of cart ticks on an idle machine), far fewer than the
    # 500 of the whole duration: the fault ended the monitor
    assert 10 <= len(table) == summary["frames"] < 250
    assert rrd_rows(tmp_path / "f.rrd")["gpio/speed_a"] == len(table)  # the bridge's labels


@pytest.mark.realtime
def test_silent_port_times_out(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    master, slave = os.openpty()
    try:
        code, out, err = _cli(capsys, "monitor", f"serial:{os.ttyname(slave)}",
                              "--connect-timeout", "0.3", "--out", str(tmp_path))  # fmt: skip
    finally:
        os.close(master)
        os.close(slave)
    assert code == 1
    assert out == ""
    (line,) = err.strip().splitlines()
    assert "no HEARTBEAT" in line and "0.3 s" in line
    assert not list(tmp_path.iterdir()), "no files for a cart that is not there"


@pytest.mark.realtime
def test_ctrl_c_stops_cleanly(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    csv_path = tmp_path / "c.csv"

    def interrupt_once_recording() -> None:
        deadline = time.monotonic() + 10.0
        # the CSV holds data rows once its first block is flushed (50 rows): the monitor runs
        while time.monotonic() < deadline:
            if csv_path.exists() and csv_path.read_text().count("\n") > 1:
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.02)

    thread = threading.Thread(target=interrupt_once_recording, daemon=True)
    thread.start()
    code, out, err = _cli(capsys, "monitor", "virtual", "--rerun", "off", "--out",
                          str(tmp_path), "--name", "c", "--json")  # fmt: skip
    thread.join(1.0)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["stopped"] == "interrupted" and summary["recording"] is None
    _, table = _read_csv(csv_path)
    assert len(table) == summary["frames"] >= 50


@pytest.mark.realtime
def test_virtual_cart_names_its_firmware_and_its_help_every_option(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A generation-B cart was announced as 'the bridge sketch version 2'; --help left out the
    options docs/serial.md gives (actuation_ms, usb, bridge, receive, reply_jitter_ms)."""
    from cartctl.cli import build_parser
    from cartctl.link.cart_faults import _FIELD_OF

    code, _, err = _cli(capsys, "virtual-cart", "--faults", "generation=b", "--duration", "0.05")
    assert code == 0, err
    assert "generation B" in err and "bridge sketch" not in err, err
    shown = " ".join(build_parser().subcommands["virtual-cart"].format_help().split())
    assert not [key for key in _FIELD_OF if f"{key}=" not in shown], shown


@pytest.mark.realtime
def test_virtual_cart_onboard_options(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = _cli(capsys, "virtual-cart", "--reference", "step:8")
    assert code == 2 and "--reference needs --onboard" in err
    code, out, err = _cli(capsys, "virtual-cart", "--onboard", str(PI), "--reference", "step:8",
                          "--duration", "0.05")  # fmt: skip
    assert code == 0, err
    assert out.startswith("/dev/")
    assert "on board" in err
