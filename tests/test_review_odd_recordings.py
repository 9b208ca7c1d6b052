"""Review of recordings other tools wrote: rows of a scalar series with no value or with two."""

from __future__ import annotations

from pathlib import Path

import pytest

rr = pytest.importorskip("rerun")


def _odd_recording(path: Path) -> Path:
    """A run's speed, plus a series with an empty row and one with two values a row."""
    rec = rr.RecordingStream("cartctl")
    rec.save(path)
    for i in range(5):
        rec.set_time("tick", sequence=i)
        rec.set_time("time", duration=i * 0.01)
        rec.log("motor/a/speed", rr.Scalars([float(i)]))
        rec.log("gpio/pair", rr.Scalars([float(i), 2.5 * i]))
        rec.log("gpio/gap", rr.Scalars([] if i == 2 else [float(i)]))
    rec.flush()
    rec.disconnect()
    return path


def _chunks(path: Path) -> list:
    from cartctl.cli.commands.review.recording import read_recording

    reader, entry = read_recording(path)
    return list(reader.stream(store=entry))


def test_scalar_stats_take_every_value_of_a_row_and_rows_without_one(tmp_path: Path) -> None:
    from cartctl.cli.commands.review.recording import layout, scalar_stats

    chunks = _chunks(_odd_recording(tmp_path / "odd.rrd"))
    extremes, whole = scalar_stats(chunks)
    assert extremes["gpio/pair"] == (0.0, 10.0)  # the second value of a row counts too
    assert extremes["gpio/gap"] == (0.0, 4.0)
    assert "gpio/pair" not in whole and {"gpio/gap", "motor/a/speed"} <= whole
    layout(chunks)  # no error


def test_recording_columns_ignore_other_entities(tmp_path: Path) -> None:
    from cartctl.cli.commands.review.smoothed import recording_columns

    columns = recording_columns(_chunks(_odd_recording(tmp_path / "odd.rrd")))
    assert list(columns["speed_a"]) == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert list(columns["tick"]) == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_read_recording_says_a_folder_is_a_folder(tmp_path: Path) -> None:
    from cartctl.cli.commands.review.recording import read_recording
    from cartctl.errors import DataFileError

    with pytest.raises(DataFileError, match="is a directory"):
        read_recording(tmp_path)
