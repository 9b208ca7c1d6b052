"""The monitor path closes: cart-tick time, monitor traces read by review/validate/convert, and
a review layout built from the recording's labels.

The monitor runs the virtual cart in real time for short durations (about 0.6-1.6 s each), once
per module where several tests share a recording.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.link import Gpio
from cartctl.plants.cart_monitor import Monitor, parse_labels

ROOT = Path(__file__).resolve().parents[1]
PI = ROOT / "controllers" / "pi.toml"
MODEL = ROOT / "models" / "ground.toml"
EXPORT_LABELS = "f0=speed_a,f1=speed_b,f2=voltage_a,f3=voltage_b,f4=reference_a,f5=reference_b"


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _read_csv(path: str | Path) -> tuple[list[str], np.ndarray]:
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float).reshape(-1, len(rows[0]))


# -- time from the cart's ticks, on a scripted link ---------------------------------------------


class _Rows:
    def __init__(self) -> None:
        self.rows: list[list[float]] = []

    def open(self, columns: object) -> None:
        pass

    def write(self, row: list[float]) -> None:
        self.rows.append([float(v) for v in row])

    def close(self) -> None:
        pass


class _Link:
    def __init__(self, stamps_ms: list[int]) -> None:
        self.stamps = list(stamps_ms)

    def next_gpio(self) -> tuple[Gpio, float]:
        from cartctl.errors import PlantError

        if not self.stamps:
            raise PlantError("no data from the cart on /dev/fake for 100 ms")
        return Gpio(self.stamps.pop(0), (0.0,) * 8, (0,) * 4), 0.0


def _times(stamps_ms: list[int], duration_s: float | None = None) -> list[float]:
    rows = _Rows()
    monitor = Monitor([rows], [], parse_labels(None))
    monitor.open()
    monitor.run(_Link(stamps_ms), duration_s)  # type: ignore[arg-type]
    return [r[0] for r in rows.rows]


@pytest.mark.parametrize(
    ("stamps", "ticks"),
    [
        # millis() jitter: 9, 10 and 11 ms steps are one tick each
        ([17170, 17180, 17189, 17200, 17211, 17220], [0, 1, 2, 3, 4, 5]),
        # five frames with one stamp (a late communication thread), then the stamps catch up
        ([0, 10, 252, 252, 252, 252, 252, 300, 310], [0, 1, 25, 26, 27, 28, 29, 30, 31]),
        # a lost frame: a 20 ms step is two ticks
        ([0, 10, 30, 40, 70], [0, 1, 3, 4, 7]),
        # a stamp a little behind its predecessor is not 49 days ahead
        ([100, 110, 109, 130], [0, 1, 2, 3]),
        # the u32 millisecond counter wraps
        ([2**32 - 20, 2**32 - 10, 0, 10, 20], [0, 1, 2, 3, 4]),
    ],
)
def test_time_is_the_cart_tick_times_ts(stamps: list[int], ticks: list[int]) -> None:
    times = _times(stamps)
    assert times == [k / 100 for k in ticks]  # exact: 0.03, not 0.030000000000000002
    assert all(np.diff(times) > 0)


def test_duration_counts_cart_ticks() -> None:
    stamps = [0, 10, 10, 10, 10, 10, 60, 70]  # ticks 0..5, then 6 and 7
    assert _times(stamps, duration_s=0.05) == [0.0, 0.01, 0.02, 0.03, 0.04]


# -- through the CLI: the virtual cart ---------------------------------------------------------


def test_monitor_time_with_lost_frames(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """Corrupted frames are lost: time still rises strictly, in whole ticks of 10 ms."""
    code, out, err = _cli(capsys, "monitor", "virtual:corrupt=0.2", "--duration", "0.6",
                          "--rerun", "off", "--out", str(tmp_path), "--name", "c",
                          "--json")  # fmt: skip
    assert code == 0, err
    summary = json.loads(out)
    _, table = _read_csv(tmp_path / "c.csv")
    steps_ticks = np.diff(table[:, 0]) / 0.01
    assert np.all(steps_ticks >= 1 - 1e-9)
    np.testing.assert_allclose(steps_ticks, np.round(steps_ticks), atol=1e-9)
    assert summary["link"]["crc_errors"] > 0
    assert np.any(steps_ticks > 1.5)  # 1 − 0.8⁶⁰ ≈ 1 − 2e-6: some GPIO was lost
    # every tick of the cart is a row or a gap: rows + missing ticks = the ticks spanned
    assert len(table) + int(np.sum(np.round(steps_ticks) - 1)) == round(table[-1, 0] / 0.01) + 1
