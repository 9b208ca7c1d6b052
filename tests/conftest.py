"""Shared fixtures: paths to the shipped files, and the report's models."""

from __future__ import annotations

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
