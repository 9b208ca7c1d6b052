"""``cartctl convert``: a partial --map takes the other motor from the file's own channels,
channel names keep their case, and whole-number channels are written as integers.

Small logs are written in tmp_path; expectations come from the text of those files, read here
with plain ``csv``/``numpy``, not from the reader under test.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main

LABELS = ["speedA", "speedB", "voltA", "voltB", "posA", "Pos_B", "FloatIn6", "FloatIn7",
          "echo", "Tick", "IntIn2", "IntIn3"]  # fmt: skip


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _channels(n: int = 12) -> np.ndarray:
    """n ticks of 12 channels: distinct float values, whole numbers in the last four."""
    rng = np.random.default_rng(7)
    floats = np.round(rng.uniform(-10.0, 10.0, size=(n, 8)), 4)
    ints = np.column_stack([100 + np.arange(n), 5000 + np.arange(n), np.ones(n), np.zeros(n)])
    return np.column_stack([floats, ints])


def _qrc6(path: Path, values: np.ndarray) -> Path:
    lines = ["QGPIORecord, QRC v6.0.2, 14-03-2024 @ 10:05:31, Ubuntu 22.04.4 LTS, x86_64",
             "Time, " + ", ".join(LABELS)]  # fmt: skip
    for k, row in enumerate(values):
        lines.append(", ".join([str(5000 + 10 * k), *(f"{v:g}" for v in row)]))
    path.write_text("\n".join(lines) + "\n")
    return path


def _qrc5(path: Path, values: np.ndarray) -> Path:
    labels = "".join(f"<value>{x}</value>" for x in ["time", *LABELS])
    rows = "".join(
        "<row>" + "\t".join([str(17170 + 10 * k), *(f"{v:g}" for v in row)]) + "</row>\n"
        for k, row in enumerate(values)
    )
    path.write_text(
        "<QGPIORecord>\n<version>2.0</version>\n<comment></comment>\n"
        f"<labels>{labels}</labels>\n<data>\n{rows}</data>\n</QGPIORecord>\n"
    )
    return path


def _read(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


@pytest.mark.parametrize("maker", [_qrc5, _qrc6])
def test_partial_map_takes_motor_b_from_its_own_channels(
    maker, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    values = _channels()
    log = maker(tmp_path / "log", values)
    out = tmp_path / "out.csv"
    code, stdout, err = _cli(capsys, "convert", str(log), "--map",
                             "voltage_a=voltA,speed_a=speedA", "--out", str(out), "--json")  # fmt: skip
    assert code == 0, err
    header, rows = _read(out)
    table = np.array(rows, dtype=float)
    column = {name: table[:, j] for j, name in enumerate(header)}
    # the file's own voltB and speedB, not zeros
    np.testing.assert_array_equal(column["voltage_b"], values[:, LABELS.index("voltB")])
    np.testing.assert_array_equal(column["speed_b"], values[:, LABELS.index("speedB")])
    np.testing.assert_array_equal(column["voltage_a"], values[:, LABELS.index("voltA")])
    assert "voltB" not in header and "speedB" not in header  # used, so not kept twice
    # the other channels keep their names, case included
    assert header[5:] == ["posA", "Pos_B", "FloatIn6", "FloatIn7", "echo", "Tick", "IntIn2",
                          "IntIn3"]  # fmt: skip
    summary = json.loads(stdout)
    assert summary["columns"]["voltage_b"]["max"] == values[:, 3].max()


def test_integer_channels_are_written_as_integers(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    values = _channels()
    log = _qrc5(tmp_path / "log.xml", values)
    out = tmp_path / "out.csv"
    code, _, err = _cli(capsys, "convert", str(log), "--map", "voltage_a=voltA,speed_a=speedA",
                        "--out", str(out))  # fmt: skip
    assert code == 0, err
    header, rows = _read(out)
    for name, first in (("echo", "100"), ("Tick", "5000"), ("IntIn2", "1"), ("IntIn3", "0")):
        texts = [row[header.index(name)] for row in rows]
        assert texts[0] == first
        assert all(t.lstrip("-").isdigit() for t in texts), (name, texts[:3])
    assert rows[1][header.index("echo")] == "101"
    # the contract's columns stay floats (time, voltages, speeds)
    assert rows[0][0] == "0.0" and "." in rows[0][header.index("voltage_a")]
    # and the file reads back to the same numbers
    code, _, err = _cli(capsys, "convert", str(out), "--out", str(tmp_path / "again.csv"))
    assert code == 0, err
    assert (tmp_path / "again.csv").read_text() == out.read_text()


def test_foreign_csv_partial_map_and_case(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "foreign.csv"
    rows = [[k * 0.01, 1.5 * k, -0.5 * k, 2.0, -3.0, 7 * k] for k in range(6)]
    path.write_text(
        "t,volt_a,volt_b,Speed_A,Speed_B,Count\n"
        + "".join(",".join(f"{v:g}" for v in r) + "\n" for r in rows)
    )
    out = tmp_path / "out.csv"
    code, _, err = _cli(capsys, "convert", str(path), "--map",
                        "time_s=t,voltage_a=volt_a,speed_a=Speed_A", "--out", str(out))  # fmt: skip
    assert code == 0, err
    header, text = _read(out)
    assert header == ["time_s", "voltage_a", "voltage_b", "speed_a", "speed_b", "Count"]
    table = np.array(text, dtype=float)
    np.testing.assert_array_equal(table[:, 2], [r[2] for r in rows])  # volt_b
    np.testing.assert_array_equal(table[:, 4], [r[4] for r in rows])  # Speed_B
    assert [r[5] for r in text] == [str(7 * k) for k in range(6)]


def test_partial_map_without_counterparts_still_zero_fills(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """Only one of motor b's counterparts exists: motor b stays unmapped (zeros), as before."""
    log = _qrc6(tmp_path / "log.csv", _channels())
    log.write_text(log.read_text().replace("speedB", "other"))
    out = tmp_path / "out.csv"
    code, _, err = _cli(capsys, "convert", str(log), "--map", "voltage_a=voltA,speed_a=speedA",
                        "--out", str(out))  # fmt: skip
    assert code == 0, err
    header, rows = _read(out)
    table = np.array(rows, dtype=float)
    assert not table[:, header.index("voltage_b")].any()
    assert "voltB" in header and "other" in header


def test_convert_out_over_a_traces_name_leaves_no_stale_meta_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A log converted onto an earlier trace's name kept that trace's meta file beside it, so
    identify took the earlier recording's loop delay for the log (unknown); converting a trace
    onto itself keeps its own."""
    log = _qrc6(tmp_path / "log.csv", _channels(40))
    out = tmp_path / "run.csv"
    (tmp_path / "run.meta.toml").write_text(
        'format = "cartctl-trace-meta/1"\nplant = "sim (models/ground.toml)"\nloop_delay_ticks = 3\n'
    )
    code, _, err = _cli(capsys, "convert", str(log), "--map", "voltage_a=voltA,speed_a=speedA",
                        "--out", str(out))  # fmt: skip
    assert code == 0, err
    assert not (tmp_path / "run.meta.toml").exists()
    (tmp_path / "run.meta.toml").write_text(
        'format = "cartctl-trace-meta/1"\nplant = "sim (models/ground.toml)"\nloop_delay_ticks = 3\n'
    )
    code, _, err = _cli(capsys, "convert", str(out), "--out", str(tmp_path / "." / "run.csv"))
    assert code == 0, err
    assert (tmp_path / "run.meta.toml").is_file()


def test_convert_out_to_a_new_name_carries_the_traces_meta_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A cartctl trace converted to a new name lost its meta file: identify on the copy did not
    know the loop delay it was recorded with (its model file had no loop_delay_ticks)."""
    trace, copy = tmp_path / "e.csv", tmp_path / "copy.csv"
    code, _, err = _cli(capsys, "excite", "--amplitude", "6", "--cycles", "1", "--out", str(trace))
    assert code == 0, err
    code, _, err = _cli(capsys, "convert", str(trace), "--out", str(copy))
    assert code == 0, err
    assert (tmp_path / "copy.meta.toml").read_text() == (tmp_path / "e.meta.toml").read_text()
    code, out, err = _cli(capsys, "identify", str(copy), "--json")
    assert code == 0, err
    assert json.loads(out)["loop_delay_ticks"] == 1
