"""Model and controller files are versioned: version 2 is written, version 1 still reads the same.

``tests/data/format-v1/`` holds ``models/ground.toml`` and ``controllers/pi.toml`` byte for byte as
cartctl shipped them in version 1 (the controller's ``[model] sha256`` is that model's hash).
Each test copies them into its own folder, as a user's older files would be.
"""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path

import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models, save_models
from cartctl.design.controllerfile import load_controller

ROOT = Path(__file__).resolve().parents[1]
V1 = Path(__file__).resolve().parent / "data" / "format-v1"


@pytest.fixture
def v1(tmp_path: Path) -> Path:
    """A folder holding the version-1 model and controller, as a user's files."""
    shutil.copytree(V1, tmp_path / "v1")
    return tmp_path / "v1"


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    code, out, err = _cli(capsys, *argv)
    assert code == 0, err
    return json.loads(out)


def test_the_copies_are_version_1_and_the_shipped_files_version_2(v1: Path) -> None:
    for relative in ("models/ground.toml", "controllers/pi.toml"):
        old = tomllib.loads((v1 / relative).read_text(encoding="utf-8"))
        new = tomllib.loads((ROOT / relative).read_text(encoding="utf-8"))
        kind = relative.split("/")[0][:-1]  # model, controller
        assert old["format"] == f"cartctl-{kind}/1" and new["format"] == f"cartctl-{kind}/2"


def test_a_version_1_model_inspects_as_the_version_2_one(
    capsys: pytest.CaptureFixture[str], v1: Path
) -> None:
    old = _json(capsys, "inspect", str(v1 / "models" / "ground.toml"), "--json")
    new = _json(capsys, "inspect", str(ROOT / "models" / "ground.toml"), "--json")
    assert old == new
    assert old["motors"]["a"]["num"] == pytest.approx([0.6466, -0.07751])  # the report's a, b


def test_a_version_1_controller_loads_and_runs_as_the_version_2_one(
    capsys: pytest.CaptureFixture[str], v1: Path
) -> None:
    old = load_controller(v1 / "controllers" / "pi.toml")
    new = load_controller(ROOT / "controllers" / "pi.toml")
    assert not old.model_changed()  # its sha256 is the v1 model's, copied byte for byte
    assert Path(old.model_path).resolve() == (v1 / "models" / "ground.toml").resolve()
    same = ("method", "period_s", "voltage_limit_v", "request", "motors", "loop_delay_ticks")
    assert all(getattr(old, name) == getattr(new, name) for name in same)
    assert old.loop_site == new.loop_site == "onboard"
    argv = ("run", "--fast", "--duration", "1", "--rerun", "off", "--json", "--controller")
    runs = [
        _json(capsys, *argv, str(controller), "--out", str(v1 / f"logs{i}"))
        for i, controller in enumerate((v1 / "controllers" / "pi.toml", "controllers/pi.toml"))
    ]
    assert runs[0]["motors"] == runs[1]["motors"] and runs[0]["ticks"] == 101


def test_new_files_are_written_as_version_2(capsys: pytest.CaptureFixture[str], v1: Path) -> None:
    model = save_models(load_models(v1 / "models" / "ground.toml"), v1 / "new" / "ground.toml")
    assert tomllib.loads(model.read_text(encoding="utf-8"))["format"] == "cartctl-model/2"
    out = v1 / "new" / "pi.toml"
    code, _, err = _cli(capsys, "design", str(model), "--method", "pi", "--out", str(out))
    assert code == 0, err
    assert tomllib.loads(out.read_text(encoding="utf-8"))["format"] == "cartctl-controller/2"


@pytest.mark.parametrize(
    ("relative", "argv", "known"),
    [
        ("models/ground.toml", ("inspect",), "'cartctl-model/1' and 'cartctl-model/2'"),
        ("controllers/pi.toml", ("run", "--fast", "--rerun", "off", "--controller"),
         "'cartctl-controller/1' and 'cartctl-controller/2'"),
    ],
)  # fmt: skip
def test_an_unknown_version_is_refused_in_one_line_naming_the_file_and_the_versions(
    capsys: pytest.CaptureFixture[str], v1: Path, relative: str, argv: tuple[str, ...], known: str
) -> None:
    path = v1 / relative
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace('/1"', '/3"', 1), encoding="utf-8")
    code, out, err = _cli(capsys, *argv, str(path))
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1, err
    assert str(path) in err and "/3'" in err and known in err
