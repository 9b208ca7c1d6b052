"""Shared fixtures: paths to the shipped files, the report's models, and a checkout-like folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
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
