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
from cartctl.link.cart_monitor import Monitor, parse_labels
from cartctl.link.dialect import Gpio

ROOT = Path(__file__).resolve().parents[1]
PI = ROOT / "controllers" / "pi.toml"
MODEL = ROOT / "models" / "ground.toml"


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _read_csv(path: str | Path) -> tuple[list[str], np.ndarray]:
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float).reshape(-1, len(rows[0]))


def _lines(path: str | Path) -> list[list[str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.reader(f))


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


@pytest.mark.realtime
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


# -- monitor traces read by review, validate and convert -----------------------------------------


def _quiet_cli(*argv: str) -> tuple[int, str, str]:
    """``main`` with stdout and stderr captured, for module-scoped fixtures (no capsys there)."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def monitor_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 1.2 s monitor of the on-board PI with no options but the reference (saved .rrd): the
    firmware's marker names its channels; and the same trace with QRoboticsCenter's default
    labels (FloatIn0..), as a firmware without the marker gives it."""
    out = tmp_path_factory.mktemp("monitor")
    code, _, err = _quiet_cli("monitor", "virtual", "--onboard", str(PI), "--reference",
                              "step:8:0.1", "--duration", "1.2", "--rerun", "save", "--out",
                              str(out), "--name", "pi")  # fmt: skip
    assert code == 0, err
    (out / "pi.stderr").write_text(err, encoding="utf-8")
    lines = _lines(out / "pi.csv")
    defaults = [*(f"FloatIn{i}" for i in range(8)), *(f"IntIn{i}" for i in range(4))]
    with open(out / "plain.csv", "w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows([["time_s", "tick", *defaults], *lines[1:]])
    return {"labelled": out / "pi.csv", "rrd": out / "pi.rrd", "plain": out / "plain.csv",
            "stderr": out / "pi.stderr"}  # fmt: skip


@pytest.mark.realtime
def test_monitor_names_the_onboard_firmwares_channels(monitor_files: dict[str, Path]) -> None:
    """The trace columns from the export's layout (floats 0-5), told by float 6 = 1001."""
    header, table = _read_csv(monitor_files["labelled"])
    assert header[:9] == ["time_s", "tick", "speed_a", "speed_b", "voltage_a", "voltage_b",
                          "reference_a", "reference_b", "firmware_id"]  # fmt: skip
    assert np.all(table[:, header.index("firmware_id")] == 1001.0)
    late = table[:, 0] > 0.8  # the step to 8 rad/s at 0.1 s is tracked
    assert np.all(table[late, header.index("reference_a")] == 8.0)
    assert abs(np.mean(table[late, header.index("speed_a")]) - 8.0) < 0.5
    (line,) = [x for x in monitor_files["stderr"].read_text().splitlines()
               if x.startswith("firmware:")]  # fmt: skip
    assert "on-board controller" in line and "float 6 = 1001" in line
    assert "f0=speed_a" in line and "f5=reference_b" in line


@pytest.mark.realtime
def test_monitor_trace_time_is_whole_ticks(monitor_files: dict[str, Path]) -> None:
    _, table = _read_csv(monitor_files["labelled"])
    steps = np.diff(table[:, 0])
    assert np.all(steps > 0)
    np.testing.assert_allclose(steps / 0.01, np.round(steps / 0.01), atol=1e-9)


@pytest.mark.realtime
def test_review_reads_a_monitor_trace(
    monitor_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    path = monitor_files["labelled"]
    code, out, err = _cli(capsys, "review", str(path), "--json")
    assert code == 0, err
    summary = json.loads(out)
    header, table = _read_csv(path)
    t = table[:, 0]
    assert summary["ticks"] == len(table) and summary["duration_s"] == pytest.approx(t[-1] - t[0])
    assert summary["trace_kind"] == "monitor" and summary["metrics_signal"] == "speed"
    assert summary["deadline_misses"] is None and summary["compute_us"]["p99"] is None
    for m in "ab":
        r, y = table[:, header.index(f"reference_{m}")], table[:, header.index(f"speed_{m}")]
        u = table[:, header.index(f"voltage_{m}")]
        entry = summary["motors"][m]
        # independent figures from the file: rms tracking error and the largest |voltage|
        assert entry["rms_error"] == pytest.approx(np.sqrt(np.mean((r - y) ** 2)), rel=1e-9)
        assert entry["max_abs_voltage"] == pytest.approx(np.max(np.abs(u)), rel=1e-9)
        # the 10-90 % rise of the 8 rad/s step lies between the samples around its crossings
        k10, k90 = int(np.argmax(y >= 0.8)), int(np.argmax(y >= 7.2))
        assert t[k90 - 1] - t[k10] - 1e-9 <= entry["rise_time_s"] <= t[k90] - t[k10 - 1] + 1e-9
    code, out, err = _cli(capsys, "review", str(path))
    assert code == 0, err
    assert "no loop timing" in out.splitlines()[0]


@pytest.mark.realtime
def test_validate_and_convert_read_a_monitor_trace(
    monitor_files: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = monitor_files["labelled"]
    code, out, err = _cli(capsys, "validate", str(MODEL), str(path), "--json")
    assert code == 0, err
    result = json.loads(out)
    assert set(result["motors"]) == {"a", "b"} and result["data"] == str(path)
    # the on-board PI's voltages drive the ground model close to the measured speeds
    assert all(30.0 < result["motors"][m]["fit_simulation_percent"] <= 100.0 for m in "ab")
    converted = tmp_path / "c.csv"
    code, out, err = _cli(capsys, "convert", str(path), "--out", str(converted), "--json")
    assert code == 0, err
    header, table = _read_csv(path)
    new_header, new_table = _read_csv(converted)
    assert new_header[:5] == ["time_s", "voltage_a", "voltage_b", "speed_a", "speed_b"]
    for name in header:
        np.testing.assert_array_equal(new_table[:, new_header.index(name)],
                                      table[:, header.index(name)])  # fmt: skip
    assert json.loads(out)["ticks"] == len(table)
    # channels keep the form the monitor wrote them in: float channels as floats, ints as ints
    first = {name: text for name, text in zip(new_header, _lines(converted)[1], strict=True)}
    source = {name: text for name, text in zip(header, _lines(path)[1], strict=True)}
    for name in ("tick", "IntIn0", "IntIn3", "reference_a", "FloatIn7"):
        assert first[name] == source[name], name
    assert first["tick"] == "0" and first["reference_a"] == "0.0"


@pytest.mark.realtime
@pytest.mark.parametrize("command", ["review", "validate", "convert"])
def test_unlabelled_monitor_trace_is_one_line_naming_the_columns(
    command: str, monitor_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    path = str(monitor_files["plain"])
    argv = [command, str(MODEL), path] if command == "validate" else [command, path]
    code, out, err = _cli(capsys, *argv)
    assert code == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert "monitor" in line and "voltage_a, voltage_b, speed_a, speed_b" in line
    assert "--labels f0=speed_a" in line and "FloatIn0" in line


@pytest.mark.realtime
def test_unlabelled_monitor_trace_with_a_map(
    monitor_files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    path = str(monitor_files["plain"])
    code, out, err = _cli(capsys, "review", path, "--json", "--map",
                          "voltage_a=FloatIn2,speed_a=FloatIn0,reference_a=FloatIn4")  # fmt: skip
    assert code == 0, err
    assert list(json.loads(out)["motors"]) == ["a"]
    code, out, err = _cli(capsys, "review", path, "--map", "voltage_a=FloatIn2,speed_a=FloatIn0")
    assert code == 2
    (line,) = err.strip().splitlines()
    assert "no reference_a" in line and "validate" in line
    assert "--labels" not in line  # speed and voltage are named: no relabelling hint


# -- the review layout of a monitor recording ----------------------------------------------------


@pytest.mark.realtime
def test_review_layout_of_a_monitor_is_built_from_its_labels(
    monitor_files: dict[str, Path], tmp_path: Path, blueprint_views, rrd_rows
) -> None:
    from rerun.chunk import RrdReader

    from cartctl.cli.commands.review.recording import layout

    reader = RrdReader(monitor_files["rrd"])
    chunks = list(reader.stream(store=reader.recordings()[0]))
    saved = tmp_path / "review.rbl"
    layout(chunks).save("cartctl", saved)
    views = blueprint_views(saved)
    header, table = _read_csv(monitor_files["labelled"])
    column = {name: table[:, j] for j, name in enumerate(header)}
    for m in "ab":
        speed = views[f"Motor {m.upper()}: speed (rad/s)"]
        assert speed["origin"] == "/gpio"
        assert sorted(speed["contents"]) == [f"$origin/reference_{m}", f"$origin/speed_{m}"]
        both = np.concatenate([column[f"reference_{m}"], column[f"speed_{m}"]])
        lo, hi = speed["range"]
        assert lo < min(both.min(), 0.0) and max(both.max(), 0.0) < hi  # the step to 8 rad/s
        voltage = views[f"Motor {m.upper()}: voltage (V)"]
        assert voltage["contents"] == [f"$origin/voltage_{m}"]
        lo, hi = voltage["range"]
        assert lo < column[f"voltage_{m}"].min() and column[f"voltage_{m}"].max() < hi
    # every recorded channel is in one view; nothing refers to the run's motor/... entities
    recorded = {e for e in rrd_rows(monitor_files["rrd"]) if e.startswith("gpio/")}
    shown = [c.replace("$origin", v["origin"].strip("/")) for v in views.values()
             for c in v["contents"]]  # fmt: skip
    assert sorted(shown) == sorted([*recorded, "cart/**"])  # and the cart's messages
    assert all(not v["origin"].startswith("/motor") for v in views.values())
    assert views["Whole-number channels"]["contents"][-4:] == [
        f"$origin/IntIn{i}" for i in range(4)
    ]


@pytest.mark.realtime
def test_review_screenshot_of_a_monitor_shows_the_lines(
    monitor_files: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from cartctl.cli.commands.review import vulkan_available
    from cartctl.sinks.rerun_layout import STYLES

    if not vulkan_available():
        pytest.skip("no Vulkan driver (apt-get install mesa-vulkan-drivers libvulkan1)")
    from PIL import Image  # a dependency of rerun-sdk

    out = tmp_path / "monitor.png"
    code, _, err = _cli(capsys, "review", str(monitor_files["rrd"]), "--screenshot", str(out))
    assert code == 0, err
    image = np.asarray(Image.open(out).convert("RGB")).astype(int)
    height = image.shape[0]
    plots = image[height // 20 : height - height // 20]

    def pixels_near(entity: str) -> int:
        colour = np.array(STYLES[entity].color)
        return int((np.abs(plots - colour).sum(axis=2) < 40).sum())

    # the monitor's speed and voltage lines, drawn in the run's colours (empty panels before)
    for entity in ("motor/a/speed", "motor/a/reference", "motor/a/voltage"):
        assert pixels_near(entity) > 300, entity


def test_monitor_over_a_runs_name_leaves_no_stale_meta_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A monitor trace written over a run's (same --out and --name) kept the run's meta file
    beside it: review smoothed with the run's model, identify took the run's loop delay; with
    ``--rerun off`` the run's recording stayed too (``review x.rrd`` showed the run). The run's
    trace itself is no longer replaced (refused, as its line says: remove it); its meta file and
    recording left behind go when the monitor writes its trace."""
    code, _, err = _cli(capsys, "run", "--fast", "--duration", "0.5", "--controller", str(PI),
                        "--rerun", "save", "--out", str(tmp_path), "--name", "x")  # fmt: skip
    assert code == 0, err
    assert (tmp_path / "x.meta.toml").is_file() and (tmp_path / "x.rrd").is_file()
    argv = ["monitor", "virtual", "--onboard", str(PI), "--duration", "0.6", "--rerun", "off",
            "--out", str(tmp_path), "--name", "x"]  # fmt: skip
    code, _, err = _cli(capsys, *argv)
    assert code == 2 and "x.csv holds a run's trace; cartctl monitor replaces only" in err, err
    (tmp_path / "x.csv").unlink()
    code, _, err = _cli(capsys, *argv)
    assert code == 0, err
    assert not (tmp_path / "x.meta.toml").exists()  # the meta file of a trace no longer there
    assert not (tmp_path / "x.rrd").exists()  # nor the recording
    code, out, err = _cli(capsys, "review", str(tmp_path / "x.csv"), "--json")
    assert code == 0, err
    review = json.loads(out)
    assert review["trace_kind"] == "monitor" and review["smoothed"]["model"] is None
