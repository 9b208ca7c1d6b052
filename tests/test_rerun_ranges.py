"""Readable y axes in the Rerun layout: ranges from what a run knows (its reference, the voltage
limit) stored in the recording's blueprint, and from the recorded values when ``review`` shows it.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main

ROOT = Path(__file__).resolve().parents[1]
PI = ROOT / "controllers" / "pi.toml"


def _run(capsys: pytest.CaptureFixture[str], tmp_path: Path, *extra: str) -> Path:
    code = main(["run", "--fast", "--duration", "1", "--model", str(ROOT / "models" / "ground.toml"),
                 "--controller", str(PI), "--rerun", "save", "--out", str(tmp_path), "--name", "r",
                 "--json", *extra])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 0, err
    return Path(json.loads(out)["recording"])


def test_run_blueprint_carries_the_ranges(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, blueprint_views
) -> None:
    path = _run(capsys, tmp_path, "--reference", "step:8:0.2", "--reference-b", "const:-4")
    views = blueprint_views(path)
    # speed: the reference's span and 0, with a quarter of the span to spare on each side
    assert views["Motor A: speed (rad/s)"]["range"] == pytest.approx((-2.0, 10.0))
    assert views["Motor B: speed (rad/s)"]["range"] == pytest.approx((-5.0, 1.0))
    # voltage: ± the controller file's limit, 5 % to spare
    limit = tomllib.loads(PI.read_text())["voltage_limit_v"]
    for m in "AB":
        assert views[f"Motor {m}: voltage (V)"]["range"] == pytest.approx((-1.05 * limit,
                                                                           1.05 * limit))  # fmt: skip
    assert views["Loop timing (µs)"]["range"] is None  # unknown before the run: the viewer fits


def test_run_blueprint_follows_a_lower_voltage_limit(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, blueprint_views
) -> None:
    views = blueprint_views(_run(capsys, tmp_path, "--voltage-limit", "6"))
    assert views["Motor A: voltage (V)"]["range"] == pytest.approx((-6.3, 6.3))
    assert views["Motor A: speed (rad/s)"]["range"] == pytest.approx((-2.5, 12.5))  # step:10


def _values(path: Path) -> dict[str, np.ndarray]:
    """Every scalar of each entity of a recording (read with pyarrow, not the code under test)."""
    import pyarrow.compute as pc
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    values: dict[str, list[float]] = {}
    for chunk in reader.stream(store=reader.recordings()[0]):
        batch = chunk.to_record_batch()
        if not chunk.is_static and "Scalars:scalars" in batch.schema.names:
            flat = pc.list_flatten(batch.column("Scalars:scalars")).to_pylist()
            values.setdefault(chunk.entity_path.strip("/"), []).extend(flat)
    return {k: np.array(v) for k, v in values.items()}


def test_review_layout_spans_the_recorded_values(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, blueprint_views
) -> None:
    from rerun.chunk import RrdReader

    from cartctl.cli.commands.review.recording import layout

    path = _run(capsys, tmp_path, "--reference", "square:6:0.4")
    reader = RrdReader(path)
    chunks = list(reader.stream(store=reader.recordings()[0]))
    saved = tmp_path / "review.rbl"
    layout(chunks).save("cartctl", saved)
    views = blueprint_views(saved)
    values = _values(path)
    for m in "ab":
        speeds = np.concatenate([values[f"motor/{m}/{s}"] for s in ("reference", "speed")])
        lo, hi = views[f"Motor {m.upper()}: speed (rad/s)"]["range"]
        assert lo < speeds.min() and speeds.max() < hi
        assert hi - lo <= 1.3 * (max(speeds.max(), 0) - min(speeds.min(), 0))
        volts = values[f"motor/{m}/voltage"]
        lo, hi = views[f"Motor {m.upper()}: voltage (V)"]["range"]
        assert lo < volts.min() and volts.max() < hi
    lo, hi = views["Loop timing (µs)"]["range"]  # a simulated clock's zeros: a span of 10 µs
    assert lo < 0.0 < 10.0 < hi
