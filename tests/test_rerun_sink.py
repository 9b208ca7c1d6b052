"""The Rerun sink (its entity paths are a contract) and ``cartctl review FILE.rrd``.

A few hundred synthetic rows go through :class:`RerunSink` into a ``.rrd`` in ``tmp_path``, which
is read back with ``rerun.chunk.RrdReader``: entity paths, timelines, row counts and values. The
screenshot test renders the layout in the headless viewer and is skipped where no Vulkan driver
is installed (``apt-get install mesa-vulkan-drivers libvulkan1``).
"""

from __future__ import annotations

import json
import urllib.request
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from cartctl.cli import main
from cartctl.cli.commands import review
from cartctl.errors import InputError
from cartctl.sinks.base import TRACE_COLUMNS, TRUE_SPEED_COLUMNS, Sink
from cartctl.sinks.rerun_layout import ENTITY_PATHS, STYLES, blueprint
from cartctl.sinks.rerun_problems import display_available
from cartctl.sinks.rerun_sink import RecordingError, RecordingWarning, RerunSink

CONTRACT_PATHS = (
    "motor/a/reference",
    "motor/a/speed",
    "motor/a/estimate",
    "motor/a/voltage",
    "motor/b/reference",
    "motor/b/speed",
    "motor/b/estimate",
    "motor/b/voltage",
    "loop/period_error_us",
    "loop/compute_us",
)
COLUMNS = (*TRACE_COLUMNS, *TRUE_SPEED_COLUMNS)
N_ROWS = 305  # not a multiple of batch_ticks: close() must flush a partial block


def synthetic_rows(n: int = N_ROWS, seed: int = 0) -> np.ndarray:
    """Step responses of two first-order motors with noise, in COLUMNS order (shape (n, 14))."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    data: dict[str, np.ndarray] = {"time_s": t, "tick": np.arange(n, dtype=float)}
    for motor, tau in (("a", 0.08), ("b", 0.12)):
        ref = np.where(t >= 0.5, 10.0, 0.0)
        true = ref * (1 - np.exp(-np.clip(t - 0.5, 0, None) / tau))
        data[f"reference_{motor}"] = ref
        data[f"true_speed_{motor}"] = true
        data[f"speed_{motor}"] = true + rng.normal(0, 0.3, n)
        data[f"estimate_{motor}"] = true + rng.normal(0, 0.05, n)
        data[f"voltage_{motor}"] = np.clip(1.5 * (ref - true) + 0.9 * true, -12, 12)
    data["period_error_us"] = np.abs(rng.normal(0, 40, n))
    data["compute_us"] = 120 + rng.normal(0, 10, n)
    return np.column_stack([data[c] for c in COLUMNS])


@dataclass(frozen=True)
class Recording:
    path: Path
    rows: np.ndarray


@dataclass
class ReadBack:
    """Per entity path: rows, timelines, and the (tick, time_ns, value) columns."""

    rows: dict[str, int]
    timelines: dict[str, set[str]]
    values: dict[str, np.ndarray]
    ticks: dict[str, np.ndarray]
    times_ns: dict[str, np.ndarray]
    static_names: dict[str, str]


def write_recording(path: Path, rows: np.ndarray, **kwargs: object) -> RerunSink:
    sink = RerunSink("save", path, strict=True, **kwargs)  # type: ignore[arg-type]
    sink.open(COLUMNS)
    for row in rows.tolist():
        sink.write(row)
    sink.close()
    return sink


def read_back(path: Path) -> ReadBack:
    rows: dict[str, int] = defaultdict(int)
    timelines: dict[str, set[str]] = defaultdict(set)
    parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = defaultdict(list)
    names: dict[str, str] = {}
    for chunk in RrdReader(path).stream():
        entity = chunk.entity_path.lstrip("/")
        batch = chunk.to_record_batch()
        if chunk.is_static:
            if "SeriesLines:names" in batch.schema.names:
                names[entity] = batch.column("SeriesLines:names").to_pylist()[0][0]
            continue
        rows[entity] += chunk.num_rows
        timelines[entity].update(chunk.timeline_names)
        values = np.array([v[0] for v in batch.column("Scalars:scalars").to_pylist()])
        ticks = batch.column("tick").to_numpy()
        times = batch.column("time").cast("int64").to_numpy()
        parts[entity].append((ticks, times, values))
    ticks_by, times_by, values_by = {}, {}, {}
    for entity, pieces in parts.items():
        ticks = np.concatenate([p[0] for p in pieces])
        order = np.argsort(ticks, kind="stable")
        ticks_by[entity] = ticks[order]
        times_by[entity] = np.concatenate([p[1] for p in pieces])[order]
        values_by[entity] = np.concatenate([p[2] for p in pieces])[order]
    return ReadBack(dict(rows), dict(timelines), values_by, ticks_by, times_by, names)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Recording:
    rows = synthetic_rows()
    path = tmp_path_factory.mktemp("rerun") / "logs" / "run.rrd"
    write_recording(path, rows)
    return Recording(path, rows)


@pytest.fixture(scope="module")
def back(recording: Recording) -> ReadBack:
    return read_back(recording.path)


# -- the sink --------------------------------------------------------------------------------


def test_is_a_sink() -> None:
    assert isinstance(RerunSink("off"), Sink)


def test_every_contract_entity_path_is_recorded(back: ReadBack) -> None:
    for entity in (*CONTRACT_PATHS, "motor/a/true_speed", "motor/b/true_speed"):
        assert entity in back.rows, entity


@pytest.mark.parametrize("entity", CONTRACT_PATHS)
def test_each_path_has_both_timelines_and_every_row(back: ReadBack, entity: str) -> None:
    assert back.timelines[entity] == {"time", "tick"}
    assert back.rows[entity] == N_ROWS


@pytest.mark.parametrize(
    "column", ["speed_a", "reference_b", "estimate_b", "voltage_a", "compute_us", "true_speed_b"]
)
def test_values_round_trip(recording: Recording, back: ReadBack, column: str) -> None:
    entity = ENTITY_PATHS[column]
    expected = recording.rows[:, COLUMNS.index(column)]
    np.testing.assert_array_equal(back.ticks[entity], np.arange(N_ROWS))
    np.testing.assert_array_equal(back.values[entity], expected)


def test_time_is_a_duration_in_seconds(recording: Recording, back: ReadBack) -> None:
    time_s = recording.rows[:, COLUMNS.index("time_s")]
    np.testing.assert_allclose(back.times_ns["motor/a/speed"], time_s * 1e9, atol=1.0)
    assert back.times_ns["motor/a/speed"][-1] == pytest.approx(3.04e9)


def test_series_are_styled_once_as_static(back: ReadBack) -> None:
    assert back.static_names["motor/a/speed"] == STYLES["motor/a/speed"].name
    assert back.static_names["loop/compute_us"] == STYLES["loop/compute_us"].name


def test_file_is_complete_after_close(recording: Recording) -> None:
    reader = RrdReader(recording.path)
    (entry,) = reader.recordings()
    assert entry.application_id == "cartctl"
    assert reader.blueprints(), "the layout travels inside the recording"
    reader.store()  # needs the footer, which only a finished file has


def test_columns_are_mapped_by_name_not_position(tmp_path: Path) -> None:
    columns = ("speed_a", "time_s", "extra", "voltage_a")
    rows = np.array([[float(k), k * 0.01, -1.0, 2.0 * k] for k in range(25)])
    sink = RerunSink("save", tmp_path / "r.rrd", strict=True, batch_ticks=7)
    sink.open(columns)
    for row in rows:
        sink.write(row)
    sink.close()
    back = read_back(tmp_path / "r.rrd")
    assert set(back.rows) == {"motor/a/speed", "motor/a/voltage"}
    np.testing.assert_array_equal(back.values["motor/a/voltage"], rows[:, 3])
    np.testing.assert_array_equal(back.ticks["motor/a/speed"], np.arange(25))  # no tick column


def test_write_never_raises_and_close_warns(tmp_path: Path) -> None:
    sink = RerunSink("save", tmp_path / "r.rrd")
    sink.open(COLUMNS)
    sink.write([1.0, 2.0])  # wrong length
    sink.write(synthetic_rows(1)[0])
    with pytest.warns(RecordingWarning, match="row 0: could not broadcast"):
        sink.close()
    assert sink.rows_written == 1
    sink.close()  # a second close does nothing


def test_strict_raises_at_once(tmp_path: Path) -> None:
    sink = RerunSink("save", tmp_path / "r.rrd", strict=True)
    sink.open(COLUMNS)
    with pytest.raises(RecordingError, match="row 0"):
        sink.write([1.0, 2.0])
    with pytest.raises(RecordingError):
        sink.close()


def test_off_writes_nothing(tmp_path: Path) -> None:
    sink = RerunSink("off", tmp_path / "r.rrd", strict=True)
    sink.open(COLUMNS)
    sink.write(synthetic_rows(1)[0])
    sink.close()
    assert not (tmp_path / "r.rrd").exists()


def test_close_without_open_is_harmless() -> None:
    RerunSink("save", "never.rrd", strict=True).close()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mode": "live"}, "rerun mode"),
        ({"mode": "save"}, "needs a path"),
        ({"mode": "off", "batch_ticks": 0}, "batch_ticks"),
    ],
)
def test_bad_arguments(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(InputError, match=match):
        RerunSink(**kwargs)  # type: ignore[arg-type]


def test_needs_a_time_column(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="time_s"):
        RerunSink("save", tmp_path / "r.rrd").open(("tick", "speed_a"))


def test_viewer_problems_keep_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    sink = RerunSink("spawn", tmp_path / "r.rrd")
    sink.open(COLUMNS)
    for row in synthetic_rows(12):
        sink.write(row)
    with pytest.warns(RecordingWarning, match="no display"):
        sink.close()
    assert read_back(tmp_path / "r.rrd").rows["motor/b/speed"] == 12


def test_connect_to_no_viewer_is_quick_and_keeps_the_file(tmp_path: Path) -> None:
    sink = RerunSink("connect", tmp_path / "r.rrd", connect_url="rerun+http://127.0.0.1:9/proxy")
    sink.open(COLUMNS)
    sink.write(synthetic_rows(1)[0])
    with pytest.warns(RecordingWarning, match="no viewer is listening"):
        sink.close()
    assert read_back(tmp_path / "r.rrd").rows["motor/a/speed"] == 1


def test_display_available(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert not display_available()
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    assert display_available()


def _views(container: object) -> Iterator[object]:
    for part in getattr(container, "contents", None) or []:
        if hasattr(part, "kind"):  # a container
            yield from _views(part)
        else:
            yield part


def test_blueprint_layout() -> None:
    root = blueprint().root_container
    views = [(v.name, v.origin) for v in _views(root)]  # type: ignore[attr-defined]
    assert views == [
        ("Motor A: speed (rad/s)", "/motor/a"),
        ("Motor A: voltage (V)", "/motor/a/voltage"),
        ("Motor B: speed (rad/s)", "/motor/b"),
        ("Motor B: voltage (V)", "/motor/b/voltage"),
        ("Loop timing (µs)", "/loop"),
    ]


# -- cartctl review --------------------------------------------------------------------------


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    ("name", "content", "extra", "message"),
    [
        ("missing.rrd", None, (), "recording not found"),
        ("run.txt", "x", (), "(.rrd) or a CSV trace"),
        ("bad.rrd", "not a recording", (), "not a readable Rerun recording"),
        ("run.rrd", "x", ("--json",), "apply to CSV traces"),
        ("run.csv", "x", ("--web",), "apply to .rrd recordings"),
    ],
)
def test_review_mistakes_are_one_line(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    name: str,
    content: str | None,
    extra: tuple[str, ...],
    message: str,
) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    code, out, err = _run(capsys, "review", str(path), *extra)
    assert code == 2
    assert out == ""
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_review_without_display_says_what_to_do(
    capsys: pytest.CaptureFixture[str], recording: Recording, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code, _, err = _run(capsys, "review", str(recording.path))
    assert code == 2
    assert "--web" in err
    assert "--screenshot" in err


def test_review_csv_gives_the_metrics_of_a_known_response(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A first-order step of 10 rad/s at 0.5 s with τ = 50 ms, at 2 V: no overshoot, settled
    in the band max(2 %, 0.3506 rad/s) after τ·ln(10 / 0.3506) = 167.5 ms, i.e. at the 17th tick."""
    import csv

    t = np.arange(200) * 0.01
    onset = t >= 0.5
    speed = np.where(onset, 10.0 * (1.0 - np.exp(-(t - 0.5) / 0.05)), 0.0)
    path = tmp_path / "run.csv"
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["time_s", "voltage_a", "voltage_b", "speed_a", "speed_b", "reference_a",
                    "period_error_us", "compute_us"])  # fmt: skip
        for k in range(t.size):
            w.writerow([repr(float(t[k])), 2.0 if onset[k] else 0.0, 0.0, repr(float(speed[k])), 0.0,
                        10.0 if onset[k] else 0.0, 0.0, 0.0])  # fmt: skip
    assert main(["review", str(path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    a = summary["motors"]["a"]
    assert summary["ticks"] == 200
    assert a["overshoot_percent"] == pytest.approx(0.0, abs=1e-9)
    assert a["max_abs_voltage"] == 2.0
    assert a["settling_time_s"] == pytest.approx(0.17, abs=0.0101)
    assert a["steady_state_error"] == pytest.approx(10.0 * np.exp(-1.49 / 0.05), abs=1e-6)


def test_review_web_serves_the_viewer(
    recording: Recording, capsys: pytest.CaptureFixture[str]
) -> None:
    pages: list[bytes] = []

    def fetch(url: str) -> None:
        with urllib.request.urlopen(url, timeout=10) as response:
            pages.append(response.read())

    url = review.serve_web(recording.path, wait=fetch)
    assert url.startswith("http://127.0.0.1:")
    assert "?url=rerun%2Bhttp" in url
    assert b"<html" in pages[0].lower()
    assert url in capsys.readouterr().out


@pytest.mark.skipif(
    not review.vulkan_available(),
    reason="no Vulkan driver (apt-get install mesa-vulkan-drivers libvulkan1)",
)
def test_review_screenshot_draws_the_lines(
    recording: Recording, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from PIL import Image  # a dependency of rerun-sdk

    out = tmp_path / "shots" / "run.png"
    code, stdout, err = _run(capsys, "review", str(recording.path), "--screenshot", str(out))
    assert code == 0, err
    assert str(out) in stdout
    image = np.asarray(Image.open(out).convert("RGB")).astype(int)
    height, width, _ = image.shape
    assert width >= 1280
    assert height >= 720
    plots = image[height // 20 : height - height // 20]  # without the menu and time bars
    rgb = plots.reshape(-1, 3)
    colours = np.unique((rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2])  # one int per colour
    assert len(colours) > 200  # lines, text, antialiasing

    def pixels_near(entity: str) -> int:
        colour = np.array(STYLES[entity].color)
        return int((np.abs(plots - colour).sum(axis=2) < 40).sum())

    for entity in ("motor/a/speed", "motor/a/voltage", "loop/period_error_us"):
        assert pixels_near(entity) > 300, entity


def test_closing_at_the_interpreters_exit_closes_without_a_thread(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """At exit Python 3.12+ refuses new threads (RuntimeError): the recording still closes, in
    order (flush, the file's footer, disconnect), on the calling thread."""
    import threading

    import rerun_bindings

    from cartctl.sinks.rerun_problems import disconnect

    calls: list[str] = []

    class Recording:
        def flush(self, timeout_sec: float) -> None:
            calls.append("flush")

        def to_native(self) -> object:
            return self

        def disconnect(self) -> None:
            calls.append("disconnect")

    def refuse(self: threading.Thread) -> None:
        raise RuntimeError("can't create new thread at interpreter shutdown")

    monkeypatch.setattr(threading.Thread, "start", refuse)
    monkeypatch.setattr(
        rerun_bindings, "finalize_deferred_sinks", lambda recording: calls.append("footer")
    )
    disconnect(Recording(), "rerun+http://127.0.0.1:1/proxy", None)
    assert calls == ["flush", "footer", "disconnect"]
