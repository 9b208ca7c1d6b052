"""Shared fixtures: paths to the shipped files, the report's models, a checkout-like folder, and
the rows of a Rerun recording; the hypothesis profile of the property tests."""

from __future__ import annotations

import shutil
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parents[1]

# Property tests: the same examples on every run (derandomize, no example database) and no
# per-example time limit, which a loaded machine would break. A test's own @settings adds to this.
settings.register_profile("cartctl", derandomize=True, database=None, deadline=None)
settings.load_profile("cartctl")

MODELS = ROOT / "models"


@pytest.fixture
def ground_path() -> Path:
    return MODELS / "ground.toml"


@pytest.fixture
def air_path() -> Path:
    return MODELS / "air.toml"


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder like a checkout: the shipped models and controllers, logs/ written there."""
    shutil.copytree(ROOT / "models", tmp_path / "models")
    shutil.copytree(ROOT / "controllers", tmp_path / "controllers")
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture
def rrd_rows() -> Callable[[str | Path], Counter]:
    """Rows per entity path (without the leading ``/``) of a recording's non-static chunks.

    Reading the stream needs the file's footer: a recording not closed properly fails here.
    """
    from rerun.chunk import RrdReader

    def count(path: str | Path) -> Counter:
        rows: Counter = Counter()
        for chunk in RrdReader(path).stream():
            if not chunk.is_static:
                rows[chunk.entity_path.lstrip("/")] += chunk.num_rows
        return rows

    return count


@pytest.fixture
def blueprint_views() -> Callable[[str | Path], dict[str, dict]]:
    """The views of the (first) blueprint stored in a file (.rrd or .rbl), by name: each with
    its ``origin``, ``contents`` (the query lines) and y ``range`` ((lo, hi) or None)."""
    from rerun.chunk import RrdReader

    def views(path: str | Path) -> dict[str, dict]:
        reader = RrdReader(path)
        (entry,) = reader.blueprints()[:1]
        fields: dict[str, dict] = {}
        for chunk in reader.stream(store=entry):
            batch = chunk.to_record_batch()
            parts = chunk.entity_path.strip("/").split("/")
            if parts[0] != "view" or len(parts) < 2:
                continue
            view = fields.setdefault(parts[1], {"range": None, "contents": []})
            for name in batch.schema.names:
                if ":" not in name:  # row ids and timelines
                    continue
                value = batch.column(name).to_pylist()[-1]
                if name == "ViewBlueprint:display_name":
                    view["name"] = value[0]
                elif name == "ViewBlueprint:space_origin":
                    view["origin"] = value[0]
                elif name == "ViewContents:query":
                    view["contents"] = list(value)
                elif name == "ScalarAxis:range":
                    view["range"] = tuple(value[0])
        return {view["name"]: view for view in fields.values() if "name" in view}

    return views
