"""Model files: the shipped models, round trips, and clear errors for bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cartctl.data.modelfile import ModelFile, Provenance, load_models, save_models
from cartctl.errors import CartctlError, DataFileError, MissingFileError
from cartctl.model import ArxModel


def test_shipped_ground_models_are_equation_12(ground_path: Path) -> None:
    models = load_models(ground_path)
    assert set(models.motors) == {"a", "b"}
    np.testing.assert_array_equal(models.motor("a").theta, [-0.9356, 0.2173, 0.6466, -0.07751])
    np.testing.assert_array_equal(models.motor("b").theta, [-0.9082, 0.1968, 0.6886, -0.1068])
    assert models.period_s == 0.01
    assert "equation 12" in models.provenance.source


def test_shipped_air_models_are_equation_8(air_path: Path) -> None:
    models = load_models(air_path)
    np.testing.assert_array_equal(models.motor("a").num(), [1.0812, -0.0323])
    np.testing.assert_array_equal(models.motor("b").den(), [1.0, -0.5886, 0.05778, 0.0])


def test_round_trip_keeps_models_stats_and_provenance(tmp_path: Path) -> None:
    models = ModelFile(
        motors={
            "a": ArxModel.from_theta([0.1, -0.2, 0.3], na=1, nb=2, nk=3),
            "b": ArxModel.from_theta([-0.9, 0.2, 0.6, -0.07]),
        },
        provenance=Provenance(
            "cartctl identify x.csv", "2026-11-22T10:00:00", ("x.csv",), "oe", "butter 6 20 Hz"
        ),
        stats={"a": {"theta_std": [0.01, 0.02, 0.03], "fit_simulation_percent": 91.5}, "b": {}},
    )
    path = save_models(models, tmp_path / "sub" / "m.toml")
    again = load_models(path)
    for name in ("a", "b"):
        assert again.motors[name] == models.motors[name]
    assert again.provenance == models.provenance
    assert again.stats["a"] == models.stats["a"]


def test_missing_model_file() -> None:
    with pytest.raises(MissingFileError, match=r"model file not found: nope\.toml") as info:
        load_models("nope.toml")
    assert isinstance(info.value, FileNotFoundError)
    assert isinstance(info.value, CartctlError)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("this is = = not toml", "not a valid TOML"),
        (
            'format = "other/9"\nperiod_s = 0.01\n[motors.a]\ntheta=[1]\nna=0\nnb=1\nnk=1',
            "has format 'other/9'",
        ),
        ("[motors.a]\ntheta = [1.0]\nna = 0\nnb = 1\nnk = 1", "missing key 'period_s'"),
        (
            "period_s = 0.01\n[motors.a]\nna = 2\nnb = 2\nnk = 2",
            r"missing key 'theta' in \[motors.a\]",
        ),
        ("period_s = 0.01\n[motors.c]\ntheta=[1.0]\nna=0\nnb=1\nnk=1", "unknown motor"),
        (
            "period_s = 0.01\n[motors.a]\ntheta = [1.0, 2.0]\nna = 2\nnb = 2\nnk = 2",
            "theta has 2 values",
        ),
        ('period_s = 0.01\n[motors.a]\ntheta = ["x"]\nna = 0\nnb = 1\nnk = 1', "list of numbers"),
        ("period_s = 0.01\n[motors.a]\ntheta = [1.0]\nna = 0\nnb = 1\nnk = -1", "nk"),
    ],
)
def test_bad_model_files_name_the_problem(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(DataFileError, match=message) as info:
        load_models(path)
    assert "bad.toml" in str(info.value)
