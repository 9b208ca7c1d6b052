"""Both CSV writers (the run's sink and ``write_trace``) write through :func:`csv.writer`.

The expected bytes are written out by hand: ``\\n`` line ends, no quotes around numbers, each
float as the shortest text that reads back to it, whole numbers of an integer column without a
fraction. A row of another width than the header is an error, never a short row in the file.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from cartctl.data.trace import Trace, write_trace
from cartctl.sinks.csv_sink import CsvSink


def test_the_sink_writes_the_header_and_rows_as_text_of_each_value(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    sink = CsvSink(path, flush_every=2)
    sink.open(["time_s", "tick", "f32"])
    sink.write((0.01, 1, np.float32(0.1)))  # a float32's own shortest text, not 0.10000000149…
    sink.write((np.float64(1.0) / 3.0, -0.0, 1e-20))
    sink.idle()
    sink.write((0.03, 3, 2.5))
    sink.close()
    assert path.read_bytes() == (
        b"time_s,tick,f32\n0.01,1,0.1\n0.3333333333333333,-0.0,1e-20\n0.03,3,2.5\n"
    )
    assert sink.rows_written == 3


@pytest.mark.parametrize("row", [(1.0, 2.0), (1.0, 2.0, 3.0, 4.0), ()])
def test_a_row_of_another_width_is_an_error_not_a_short_row(tmp_path: Path, row) -> None:
    path = tmp_path / "t.csv"
    sink = CsvSink(path, flush_every=1)
    sink.open(["a", "b", "c"])
    sink.write((1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match=rf"a row of {len(row)} fields under 3 columns"):
        sink.write(row)
    sink.write((4.0, 5.0, 6.0))
    sink.close()
    assert path.read_text() == "a,b,c\n1.0,2.0,3.0\n4.0,5.0,6.0\n"
    assert sink.rows_written == 2


def test_a_column_name_that_needs_quotes_reads_back(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    sink = CsvSink(path)
    names = ["time_s", 'gain "Kp", motor a']
    sink.open(names)
    sink.write((0.0, 1.5))
    sink.close()
    with path.open(newline="") as file:
        assert list(csv.reader(file)) == [names, ["0.0", "1.5"]]


def test_write_trace_writes_shortest_exact_floats_and_whole_ticks(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    third = 1.0 / 3.0
    trace = Trace(
        [0.0, 0.01], [0.1, -12.0], [0.0, 0.0], [third, 1e-300], [2.5, -0.5],
        extra={"tick": [0.0, 1.0], "reference_a": [7.0, 7.25]},
        integer_columns=frozenset({"tick"}),
    )  # fmt: skip
    write_trace(trace, path)
    assert path.read_bytes() == (
        b"time_s,voltage_a,voltage_b,speed_a,speed_b,tick,reference_a\n"
        b"0.0,0.1,0.0,0.3333333333333333,2.5,0,7.0\n"
        b"0.01,-12.0,0.0,1e-300,-0.5,1,7.25\n"
    )
    with path.open(newline="") as file:
        values = [[float(v) for v in row] for row in list(csv.reader(file))[1:]]
    assert values[0][3] == third  # the text reads back to the same float64
