"""Tests for cartctl.data (traces, the trace-column CSV) and cartctl.data.qrc (QRoboticsCenter logs)."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from cartctl.data.read import read_trace
from cartctl.data.trace import REQUIRED_COLUMNS, Trace, parse_mapping, write_trace
from cartctl.errors import CartctlError, DataFileError, DataWarning, InputError, MissingFileError

DATA = Path(__file__).parent / "data"
QRC5 = DATA / "qrc5_sample.xml"
QRC6 = DATA / "qrc6_sample.csv"
HEADER = ",".join(REQUIRED_COLUMNS)
MAP_AB = {"voltage_a": "voltA", "speed_a": "speedA", "voltage_b": "voltB", "speed_b": "speedB"}


def write(tmp_path: Path, text: str, name: str = "trace.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def csv_rows(n: int, dt_s: float = 0.01) -> str:
    return "".join(f"{k * dt_s!r},1.5,0,{0.1 * k!r},0\n" for k in range(n))


@contextmanager
def no_warnings() -> Iterator[None]:
    """A context in which any warning fails the test (proves a warning's absence)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def sample_trace(n: int = 50) -> Trace:
    rng = np.random.default_rng(1)
    speed = rng.normal(scale=20.0, size=n)
    speed[:4] = [1 / 3, -0.0, 5e-324, 1e300]  # thirds, negative zero, subnormal, huge
    return Trace.from_columns(
        {
            "time_s": np.arange(n) * 0.01,
            "voltage_a": rng.uniform(-12, 12, n),
            "voltage_b": np.zeros(n),
            "speed_a": speed,
            "speed_b": rng.normal(size=n),
            "true_speed_a": speed + rng.normal(scale=1e-3, size=n),
            "tick": np.arange(n, dtype=float),
        },
        source="made up",
    )


# --- Trace ---------------------------------------------------------------------------------------


def test_trace_accessors() -> None:
    trace = sample_trace(5)
    assert len(trace) == 5
    assert trace.voltage("a") is trace.voltage_a
    assert trace.speed("b") is trace.speed_b
    assert trace.column("tick").tolist() == [0, 1, 2, 3, 4]
    assert list(trace.columns()) == [*REQUIRED_COLUMNS, "true_speed_a", "tick"]
    assert trace.period_s == pytest.approx(0.01)
    assert all(a.dtype == np.float64 and a.ndim == 1 for a in trace.columns().values())
    assert "5 ticks" in repr(trace)


def test_trace_arrays_are_read_only_copies() -> None:
    time = np.arange(3) * 0.01
    trace = Trace(time, [0, 0, 0], [0, 0, 0], [1, 2, 3], [0, 0, 0])
    time[0] = 99.0
    assert trace.time_s[0] == 0.0
    with pytest.raises(ValueError, match="read-only"):
        trace.speed_a[0] = 5.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda t: t.voltage("c"), "motor must be 'a' or 'b', got 'c'"),
        (lambda t: t.speed("A"), "got 'A'"),
        (lambda t: t.column("reference_a"), "no column 'reference_a'.*time_s, voltage_a"),
        (lambda t: Trace.from_columns({"time_s": [0.0]}), "missing required column.*voltage_a"),
        (lambda t: Trace([0.0, 0.01], [0, 0], [0, 0], [0], [0, 0]), "'speed_a' has 1 values"),
        (lambda t: Trace([[0.0]], [0], [0], [0], [0]), "'time_s' must be 1-D"),
        (lambda t: Trace([0.0], ["x"], [0], [0], [0]), "'voltage_a' must hold numbers"),
        (lambda t: Trace([0.0], [0], [0], [0], [0], extra={"speed_a": [1]}), "repeats"),
        (lambda t: Trace([0.0], [0], [0], [0], [0], extra={"x": [1, 2]}), "'x' has 2 values"),
        (lambda t: Trace([0.0], [0], [0], [0], [0]).period_s, "two ticks or more"),
    ],
)
def test_trace_input_errors(call, match: str) -> None:
    with pytest.raises(InputError, match=match):
        call(sample_trace(5))


# --- trace-column CSV ------------------------------------------------------------------------------


def test_round_trip_is_bit_exact(tmp_path: Path) -> None:
    trace = sample_trace()
    path = tmp_path / "runs" / "today" / "trace.csv"  # parent directories are created
    write_trace(trace, path)
    again = read_trace(path)
    assert list(again.columns()) == list(trace.columns())
    for name, values in trace.columns().items():
        assert again.column(name).view(np.uint64).tolist() == values.view(np.uint64).tolist()
    assert again.source == str(path)
    assert path.read_text().splitlines()[0] == HEADER + ",true_speed_a,tick"


def test_csv_tolerates_spaces_blank_lines_crlf_and_keeps_extras(tmp_path: Path) -> None:
    text = " time_s , voltage_a,voltage_b,speed_a,speed_b, tick\r\n\r\n 0.0 , 1,0, 2.5 ,0,7\r\n"
    text += "0.01,1,0,3,0,8\r\n   \r\n0.02,1,0,3.5,0,9\r\n"
    trace = read_trace(write(tmp_path, text))
    assert trace.speed_a.tolist() == [2.5, 3.0, 3.5]
    assert trace.extra["tick"].tolist() == [7, 8, 9]


def test_csv_one_row_and_utf8_bom(tmp_path: Path) -> None:
    trace = read_trace(write(tmp_path, "\ufeff" + HEADER + "\n0,1,2,3,4\n"))
    assert trace.speed_b.tolist() == [4.0]


@pytest.mark.parametrize(
    ("text", "line", "column", "needles"),
    [
        ("", None, None, ["empty", "time_s,voltage_a"]),
        ("\n  \n\n", None, None, ["empty"]),
        ("0,1,2,3,4\n0.01,1,2,3,4\n", 1, None, ["no header", "time_s,voltage_a"]),
        (
            "time_s,voltage_a,speed_a\n0,1,2\n",
            1,
            None,
            ["missing required column(s) voltage_b, speed_b", "header has time_s, voltage_a"],
        ),
        ("time_s;voltage_a;voltage_b;speed_a;speed_b\n0;1;2;3;4\n", 1, None, ["';'"]),
        (HEADER + ",tick,tick\n0,0,0,0,0,0,0\n", 1, None, ["'tick' appears twice"]),
        ("time_s,,voltage_b,speed_a,speed_b\n0,0,0,0,0\n", 1, None, ["column 2", "no name"]),
        (HEADER + "\n", None, None, ["no data rows"]),
        (HEADER + "\n\n  \n", None, None, ["no data rows"]),
        (HEADER + "\n" + csv_rows(2) + "0.02,1,0,3\n", 4, None, ["4 fields, the header has 5"]),
        (HEADER + "\n" + csv_rows(2) + "0.02,1,0,3,0,9\n", 4, None, ["6 fields"]),
        (HEADER + "\n0,1,0,0,0\n0.01,1,0,abc,0\n", 3, "speed_a", ["'abc' is not a number"]),
        (HEADER + "\n0,1,0,0,0\n\n0.01,1,,0,0\n", 4, "voltage_b", ["an empty field"]),
        (HEADER + "\n0,1,0,0,0\n0.01,nan,0,0,0\n", 3, "voltage_a", ["nan is not a finite"]),
        (HEADER + "\n0,1,0,0,0\n0.01,1,0,0,-inf\n", 3, "speed_b", ["-inf is not a finite"]),
        (HEADER + "\n" + csv_rows(3) + "0.02,1,0,0,0\n", 5, "time_s", ["time goes from 0.02"]),
        (HEADER + "\n0.01,1,0,0,0\n0.0,1,0,0,0\n", 3, "time_s", ["must increase"]),
        (HEADER + "\n\n0,1,0,0,0\n\n\n0.01,1,0,inf,0\n", 6, "speed_a", ["inf is not"]),
        ('""\n', 1, None, ["column 1 of the header has no name"]),
    ],
)
def test_csv_errors_name_file_line_and_column(
    tmp_path: Path, text: str, line: int | None, column: str | None, needles: list[str]
) -> None:
    path = write(tmp_path, text, "bad_trace.csv")
    with pytest.raises(DataFileError) as caught:
        read_trace(path)
    message = str(caught.value)
    assert message.startswith(str(path))
    assert caught.value.line == line
    assert caught.value.column == column
    if line is not None:
        assert f"line {line}" in message
    for needle in needles:
        assert needle in message


def test_csv_header_is_checked_before_bytes_that_are_not_utf8(tmp_path: Path) -> None:
    """A byte that is not UTF-8 past the first 8 KiB read (a Latin-1 note late in a file) is
    reported only once the header has passed its checks, as it was before the single pass."""
    rows = csv_rows(2000).encode() + b"20,0,0,0,0 caf\xe9\n"
    path = tmp_path / "trace.csv"
    path.write_bytes(b"time_s,voltage_a,speed_a,speed_b\n" + rows)
    with pytest.raises(DataFileError, match="missing required column") as caught:
        read_trace(path)
    assert caught.value.line == 1
    path.write_bytes(HEADER.encode() + b",speed_a\n" + rows)
    with pytest.raises(DataFileError, match="'speed_a' appears twice"):
        read_trace(path)
    path.write_bytes(HEADER.encode() + b"\n" + rows)
    with pytest.raises(DataFileError, match="not UTF-8 text"):
        read_trace(path)


def test_csv_read_at_once_or_row_by_row_gives_the_same_trace(tmp_path: Path) -> None:
    """A plain file (np.loadtxt reads it at once) and the same rows with a blank line (the csv
    module reads them row by row): bit-identical columns, integer columns, error lines."""
    rows = [
        f"{k / 100!r},{k % 7 - 3}.25,0,{float(np.sin(k))!r},{k**0.5!r},{k}, {k}.0"
        for k in range(300)
    ]
    head = HEADER + ",tick,whole"
    plain = read_trace(write(tmp_path, "\n".join([head, *rows]) + "\n", "plain.csv"))
    spaced = "\n".join([head, *rows[:100], "", *rows[100:]]) + "\n"
    blank = read_trace(write(tmp_path, spaced, "blank.csv"))
    assert list(plain.columns()) == list(blank.columns())
    for name, values in plain.columns().items():
        assert blank.column(name).view(np.uint64).tolist() == values.view(np.uint64).tolist()
    assert plain.integer_columns == blank.integer_columns == {"tick"}
    rows[150] = rows[150].replace(",0,", ",inf,", 1)
    for name, text, line in (("plain", [head, *rows], 152), ("blank", [head, "", *rows], 153)):
        with pytest.raises(DataFileError, match="inf is not a finite") as caught:
            read_trace(write(tmp_path, "\n".join(text) + "\n", f"{name}.csv"))
        assert (caught.value.line, caught.value.column) == (line, "voltage_b")


def test_binary_file_and_directory_are_data_errors(tmp_path: Path) -> None:
    binary = tmp_path / "run.rrd"
    binary.write_bytes(b"RRF2\0\0\x01\x02")
    with pytest.raises(DataFileError, match="binary"):
        read_trace(binary)
    with pytest.raises(DataFileError, match="directory"):
        read_trace(tmp_path)


def test_missing_file() -> None:
    with pytest.raises(MissingFileError) as caught:
        read_trace("no/such/trace.csv")
    assert isinstance(caught.value, FileNotFoundError)
    assert isinstance(caught.value, CartctlError)
    assert "no/such/trace.csv" in str(caught.value)


def test_csv_with_mapping_reads_foreign_headers(tmp_path: Path) -> None:
    text = "t, u, y, note\n0,2,5,1\n0.01,2,6,1\n0.02,2,7,1\n"
    trace = read_trace(write(tmp_path, text), {"time_s": "t", "voltage_b": "u", "speed_b": "y"})
    assert trace.speed_b.tolist() == [5, 6, 7]
    assert trace.voltage_a.tolist() == [0, 0, 0]  # motor a unmapped: zeros
    assert list(trace.extra) == ["note"]


def test_csv_mapping_swaps_a_column_and_drops_the_clashing_one(tmp_path: Path) -> None:
    text = HEADER + ",true_speed_a\n0,1,0,5,0,5.5\n0.01,1,0,6,0,6.5\n"
    trace = read_trace(write(tmp_path, text), {"speed_a": "true_speed_a"})
    assert trace.speed_a.tolist() == [5.5, 6.5]
    assert trace.voltage_a.tolist() == [1, 1]  # the rest found by name
    assert trace.extra == {}  # the file's own speed_a would clash, so it is dropped


@pytest.mark.parametrize(
    ("mapping", "needles"),
    [
        ({"voltage_a": "u", "speed_a": "y"}, ["no time column", "--map time_s=<column>"]),
        ({"time_s": "t", "voltage_a": "u", "speed_a": "z"}, ["'z'", "lacks", "t, u, y"]),
        ({"time_s": "t", "voltage_a": "u"}, ["voltage_a comes from column 'u'", "speed_a"]),
        ({"time_s": "t", "reference_a": "u"}, ["no mapping for voltage/speed", "--map"]),
    ],
)
def test_csv_mapping_errors(tmp_path: Path, mapping: dict[str, str], needles: list[str]) -> None:
    path = write(tmp_path, "t,u,y\n0,1,2\n0.01,1,2\n")
    with pytest.raises(DataFileError) as caught:
        read_trace(path, mapping)
    assert str(caught.value).startswith(str(path))
    for needle in needles:
        assert needle in str(caught.value)


# --- QRC logs ------------------------------------------------------------------------------------


def test_qrc5_with_mapping() -> None:
    with no_warnings():  # 9, 10 and 11 ms steps are millis() jitter, not lost frames
        trace = read_trace(QRC5, MAP_AB)
    assert len(trace) == 20
    assert trace.time_s[0] == 0.0
    assert trace.time_s[:4] == pytest.approx([0.0, 0.010, 0.019, 0.030])
    assert trace.time_s[-1] == pytest.approx(0.190)
    assert trace.speed_a[3:6].tolist() == [2.1, 3.99, 5.691]
    assert trace.voltage_a[:4].tolist() == [0, 0, 6, 6]
    assert trace.voltage_b[4] == -3.0
    assert trace.speed_b[-1] == -7.03747
    extras = ["posA", "posB", "FloatIn6", "FloatIn7", "echo", "tick", "IntIn2", "IntIn3"]
    assert list(trace.extra) == extras
    assert trace.extra["tick"][:2].tolist() == [5000, 5001]


def test_qrc6_with_mapping_for_one_motor() -> None:
    with no_warnings():
        trace = read_trace(QRC6, {"voltage_a": "voltA", "speed_a": "speedA"})
    assert len(trace) == 20
    assert trace.time_s == pytest.approx(np.arange(20) * 0.01)
    assert trace.time_s[0] == 0.0
    assert trace.voltage_a[:3].tolist() == [0.0, -4.5, -4.5]
    assert trace.speed_a[2:4].tolist() == [-1.575, -2.9925]
    # motor b from its own channels: voltB and speedB, the counterparts of the mapped voltA, speedA
    assert trace.voltage_b[3] == 2.0 and "voltB" not in trace.extra
    assert trace.speed_b.any() and "speedB" not in trace.extra
    assert trace.extra["FloatIn10"][:3].tolist() == [0, 1, 2]  # other channels keep their case


def test_qrc_labels_named_like_columns_need_no_mapping(tmp_path: Path) -> None:
    text = QRC6.read_text().replace("speedA", "Speed_A").replace("voltA", "voltage_a")
    trace = read_trace(write(tmp_path, text))
    assert trace.voltage_a[1] == -4.5
    assert trace.speed_a[2] == -1.575


@pytest.mark.parametrize("path", [QRC5, QRC6])
def test_qrc_without_mapping_lists_labels_and_the_map_form(path: Path) -> None:
    with pytest.raises(DataFileError) as caught:
        read_trace(path)
    message = str(caught.value)
    assert message.startswith(str(path))
    assert "no mapping for voltage/speed columns" in message
    assert "speedA, speedB, voltA, voltB, posA" in message
    assert "--map voltage_a=voltA,speed_a=speedA" in message


@pytest.mark.parametrize(
    ("mapping", "needles"),
    [
        ({"voltage_a": "FloatIn2", "speed_a": "speedA"}, ["'FloatIn2'", "lacks", "speedA, speedB"]),
        ({"voltage_a": "voltA"}, ["voltage_a comes from channel 'voltA'", "speed_a from none"]),
        ({"time_s": "FloatIn6", **MAP_AB}, ["own time", "drop time_s=FloatIn6"]),
    ],
)
def test_qrc_mapping_errors(mapping: dict[str, str], needles: list[str]) -> None:
    for path in (QRC5, QRC6):
        with pytest.raises(DataFileError) as caught:
            read_trace(path, mapping)
        for needle in needles:
            assert needle in str(caught.value)


def test_qrc6_in_latin1_and_its_labels_as_column_names(tmp_path: Path) -> None:
    text = QRC6.read_text().replace("FloatIn6", "Geschw. R\u00e4d [rad/s]").replace("posB", "2nd")
    path = tmp_path / "windows.csv"
    path.write_bytes(text.encode("latin-1"))
    trace = read_trace(path, MAP_AB)
    assert {"Geschw_R_d_rad_s", "ch_2nd"} <= set(trace.extra)


def test_qrc_extra_mapping_and_repeated_labels(tmp_path: Path) -> None:
    text = QRC6.read_text().replace("FloatIn8", "x").replace("FloatIn9", "X")
    text = text.replace("FloatIn6", "p q").replace("FloatIn7", "p-q")
    trace = read_trace(write(tmp_path, text), {**MAP_AB, "reference_a": "FloatIn10"})
    assert trace.extra["reference_a"][:3].tolist() == [0, 1, 2]
    assert "FloatIn10" not in trace.extra
    assert {"x", "X"} <= set(trace.extra)  # case kept: two names
    assert {"p_q", "p_q_2"} <= set(trace.extra)  # one name twice: numbered


def qrc5_variant(tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    text = QRC5.read_text()
    assert old in text
    return write(tmp_path, text.replace(old, new, count), "log_gpio_03_14_10_05.xml")


def test_qrc5_row_with_wrong_field_count(tmp_path: Path) -> None:
    path = qrc5_variant(tmp_path, "<row>17210\t3.99\t0", "<row>17210\t3.99")
    with pytest.raises(DataFileError) as caught:
        read_trace(path, MAP_AB)
    assert str(caught.value).startswith(str(path))
    assert "row 5: 12 fields, the log has 13 columns (time and 12 channels)" in str(caught.value)


@pytest.mark.parametrize(
    ("old", "new", "needles"),
    [
        ("<row>17210\t3.99", "<row>17210\t3.99x", ["row 5", "column 'speedA'", "'3.99x'"]),
        ("<row>17210\t3.99", "<row>17210\tnan", ["row 5", "column 'speedA'", "nan"]),
        ("<row>17210", "<row>17200", ["row 5", "column 'time'", "from 17200 ms to 17200 ms"]),
        ("<QGPIORecord>", "<QPositionRecord>", ["cannot parse the XML (mismatched tag)", "line"]),
        ("<data>", "<notdata>", ["cannot parse the XML", ", line 48: "]),
        ("<value>voltA", "<value>volt&A", ["cannot parse the XML", ", line 16: "]),
    ],
)
def test_qrc5_content_errors(tmp_path: Path, old: str, new: str, needles: list[str]) -> None:
    path = qrc5_variant(tmp_path, old, new)
    with pytest.raises(DataFileError) as caught:
        read_trace(path, MAP_AB)
    for needle in needles:
        assert needle in str(caught.value)


def test_qrc5_other_record_type_and_empty_data(tmp_path: Path) -> None:
    path = qrc5_variant(tmp_path, "QGPIORecord", "QPositionRecord", count=2)
    with pytest.raises(DataFileError, match="not a QRC GPIO log"):
        read_trace(path)
    text = QRC5.read_text()
    empty = text[: text.index("<data>")] + "<data>\n\t</data>\n</QGPIORecord>\n"
    with pytest.raises(DataFileError, match="no data rows"):
        read_trace(write(tmp_path, empty, "empty.xml"), MAP_AB)


def test_qrc5_truncated_log_is_read_with_a_warning(tmp_path: Path) -> None:
    text = QRC5.read_text()
    cut = text.index("<row>17360")  # QRC stopped mid-row, before the closing tags
    path = write(tmp_path, text[: cut + 12], "cut.xml")
    with pytest.warns(DataWarning, match="without its closing tags.*19 complete rows"):
        trace = read_trace(path, MAP_AB)
    assert len(trace) == 19


def test_a_trace_cut_mid_row_by_a_kill_reads_its_whole_rows(tmp_path: Path) -> None:
    """A recording stopped mid-write (a kill, a power loss) ends in part of a row and no newline:
    its whole rows read, with a warning; a short row elsewhere is still a bad file."""
    header = ",".join(REQUIRED_COLUMNS)
    rows = [f"{k * 0.01:.2f}," + ",".join(["1.0"] * (len(REQUIRED_COLUMNS) - 1)) for k in range(5)]
    cut = header + "\n" + "\n".join(rows) + "\n0.05,1.0,1."
    with pytest.warns(DataWarning, match="last row is cut short.*5 complete rows"):
        trace = read_trace(write(tmp_path, cut, "cut.csv"))
    np.testing.assert_allclose(trace.time_s, [0.0, 0.01, 0.02, 0.03, 0.04])
    for text in (cut + "\n", header + "\n" + rows[0] + "\n0.01,1.0\n" + "\n".join(rows[2:])):
        with pytest.raises(DataFileError, match="fields, the header has"):
            read_trace(write(tmp_path, text, "short.csv"))


def test_qrc5_default_labels_when_none_given(tmp_path: Path) -> None:
    text = QRC5.read_text()
    text = text[: text.index("<labels>")] + text[text.index("</labels>") + 9 :]
    path = write(tmp_path, text, "plain.xml")
    trace = read_trace(path, {"voltage_a": "FloatIn2", "speed_a": "FloatIn0"})
    assert trace.voltage_a[2] == 6.0
    assert "IntIn1" in trace.extra


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("QPositionRecord, QRC v6.0.2, x\nTime, x\n1, 2\n", ["QPositionRecord", "only GPIO"]),
        ("QGPIORecord\n14/03/19, 10h05\n1.0\n\ntime\tFloatIn0\n", ["early QRC text log"]),
        ("QGPIORecord, QRC v6.0.2\nt, a\n1, 2\n", ["line 2", "Time, <label>"]),
        ("QGPIORecord, QRC v6.0.2\nTime, a, b\n", ["no data rows"]),
        ("QGPIORecord, QRC v6.0.2\nTime, a, b\n1, 2, 3\n2, 2\n", ["line 4", "2 fields"]),
    ],
)
def test_qrc6_errors(tmp_path: Path, text: str, needles: list[str]) -> None:
    path = write(tmp_path, text, "log_gpio.csv")
    with pytest.raises(DataFileError) as caught:
        read_trace(path, {"voltage_a": "a", "speed_a": "b"})
    assert str(caught.value).startswith(str(path))
    for needle in needles:
        assert needle in str(caught.value)


# --- sample spacing ------------------------------------------------------------------------------


def test_spacing_warning_for_a_gap_in_csv(tmp_path: Path) -> None:
    times = [0.0, 0.01, 0.02, 0.05, 0.06, 0.07, 0.075]  # a 30 ms gap at line 5, then 5 ms
    text = HEADER + "\n" + "".join(f"{t!r},0,0,0,0\n" for t in times)
    with pytest.warns(DataWarning) as record:
        read_trace(write(tmp_path, text))
    assert len(record) == 1  # once per file
    message = str(record[0].message)
    assert "2 of 6 time steps" in message
    assert "farthest is 30 ms (at line 5)" in message
    assert "the first at line 5" in message


def test_spacing_warning_for_a_lost_qrc5_frame(tmp_path: Path) -> None:
    path = qrc5_variant(tmp_path, "<row>17290", "<row>17300")  # 19 ms after 17281
    with pytest.raises(DataFileError):  # 17300 twice: not increasing
        read_trace(path, MAP_AB)
    path = qrc5_variant(tmp_path, "<row>17290", "<row>17296")  # a 15 ms step, then 4 ms
    with pytest.warns(DataWarning, match=r"2 of 19 time steps.*at row 13"):
        read_trace(path, MAP_AB)


@pytest.mark.parametrize("step_ms", [9, 10, 11])
def test_no_spacing_warning_for_millis_jitter(tmp_path: Path, step_ms: int) -> None:
    times = (np.cumsum([0] + [10, step_ms, 10, step_ms] * 5) / 1000).tolist()
    text = HEADER + "\n" + "".join(f"{t!r},0,0,0,0\n" for t in times)
    with no_warnings():
        trace = read_trace(write(tmp_path, text))
    assert len(trace) == 21


# --- write_trace refusals and parse_mapping ------------------------------------------------------


@pytest.mark.parametrize(
    ("columns", "match"),
    [
        ({"speed_a": [0.0, np.nan]}, "'speed_a' holds nan at tick 1"),
        ({"time_s": [0.0, 0.0]}, "time_s does not increase at tick 1"),
        ({"a,b": [0.0, 1.0]}, "cannot write column name 'a,b'"),
        (
            {"time_s": [], "voltage_a": [], "voltage_b": [], "speed_a": [], "speed_b": []},
            "no ticks",
        ),
    ],
)
def test_write_trace_refuses_what_read_trace_would(
    tmp_path: Path, columns: dict[str, list[float]], match: str
) -> None:
    base = {name: [0.0, 0.0] for name in REQUIRED_COLUMNS} | {"time_s": [0.0, 0.01]}
    with pytest.raises(InputError, match=match):
        write_trace(Trace.from_columns(base | columns), tmp_path / "out.csv")
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("voltage_a=FloatIn2,speed_a=FloatIn0", {"voltage_a": "FloatIn2", "speed_a": "FloatIn0"}),
        (" voltage_b = voltB , speed_b=speed B ,", {"voltage_b": "voltB", "speed_b": "speed B"}),
        ("time_s=t,reference_a=FloatIn4", {"time_s": "t", "reference_a": "FloatIn4"}),
    ],
)
def test_parse_mapping(text: str, expected: dict[str, str]) -> None:
    mapping = parse_mapping(text)
    assert mapping == expected
    assert list(mapping) == list(expected)


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("", ["empty column mapping", "NAME=LABEL"]),
        (" , ", ["empty column mapping"]),
        ("voltage_a", ["bad column mapping item 'voltage_a'", "voltage_a=FloatIn2"]),
        ("voltage_a=", ["bad column mapping item 'voltage_a='"]),
        ("=FloatIn2", ["bad column mapping item '=FloatIn2'"]),
        ("volt a=FloatIn2", ["'volt a' is not a column name"]),
        ("2speed=FloatIn0", ["'2speed' is not a column name"]),
        ("speed_A=FloatIn0", ["unknown column 'speed_A'", "did you mean 'speed_a'"]),
        ("speed_a=FloatIn0,speed_a=FloatIn1", ["'speed_a' is mapped twice"]),
    ],
)
def test_parse_mapping_errors(text: str, needles: list[str]) -> None:
    with pytest.raises(InputError) as caught:
        parse_mapping(text)
    for needle in needles:
        assert needle in str(caught.value)


def test_read_trace_checks_a_mapping_given_as_a_dict() -> None:
    with pytest.raises(InputError, match="did you mean 'voltage_a'"):
        read_trace(QRC5, {"voltag_a": "voltA"})
    with pytest.raises(InputError, match="no label"):
        read_trace(QRC5, {"voltage_a": " "})
