"""The shipped model and controller files from any folder, and in the wheel a plain install gets.

``controllers/pi.toml`` names the working folder's file when there is one, else the one shipped
with cartctl (``cartctl.choices.find_file``): in this editable install, the checkout's.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from cartctl.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_commands_find_the_shipped_files_from_another_folder(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert not (tmp_path / "models").exists() and not (tmp_path / "controllers").exists()
    model = _cli(capsys, "inspect", "models/ground.toml", "--json")
    motor_a = model["motors"]["a"]  # the report's equation 12: (a z + b) / (z³ + c z² + d z)
    assert motor_a["num"] == pytest.approx([0.6466, -0.07751])
    assert motor_a["den"][:3] == pytest.approx([1.0, -0.9356, 0.2173])
    run = _cli(capsys, "run", "--fast", "--duration", "1", "--rerun", "off", "--json")
    assert run["controller"] == "controllers/pi.toml" and run["ticks"] == 101
    assert Path(run["trace"]).resolve().is_relative_to(tmp_path)  # outputs stay here
    poles = _cli(capsys, "run", "--fast", "--duration", "1", "--rerun", "off", "--plant",
                 "physics", "--controller", "controllers/poles.toml", "--json")  # fmt: skip
    assert poles["controller_loop_delay_ticks"] == 1


def test_a_file_in_the_working_folder_comes_first(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "models").mkdir()
    text = (ROOT / "models" / "ground.toml").read_text(encoding="utf-8")
    mine = text.replace("theta = [-0.9356, 0.2173, 0.6466, -0.07751]",
                        "theta = [-0.9, 0.2, 0.6, -0.07]")  # fmt: skip
    assert mine != text
    (tmp_path / "models" / "ground.toml").write_text(mine, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    model = _cli(capsys, "inspect", "models/ground.toml", "--json")
    assert model["motors"]["a"]["num"] == pytest.approx([0.6, -0.07])  # this folder's, not ours


def test_a_missing_file_is_still_named_as_given(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    code = main(["run", "--fast", "--controller", "controllers/nope.toml"])
    _, err = capsys.readouterr()
    assert code == 2 and "controller file not found: controllers/nope.toml" in err


def test_the_wheel_ships_the_models_and_controllers(tmp_path: Path) -> None:
    source = tmp_path / "source"  # a copy: building writes build/ next to the sources
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "build")
    for name in ("pyproject.toml", "setup.py", "README.md"):
        source.mkdir(exist_ok=True)
        shutil.copy2(ROOT / name, source / name)
    for folder in ("src", "models", "controllers"):
        shutil.copytree(ROOT / folder, source / folder, ignore=ignore)
    out = tmp_path / "wheel"
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "-q", "-w", str(out)],
        capture_output=True, text=True, cwd=tmp_path,
    )  # fmt: skip
    assert built.returncode == 0, built.stderr
    (wheel,) = out.glob("cartctl-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = [f"cartctl/shipped/{folder}/{path.name}" for folder in ("models", "controllers")
               for path in sorted((ROOT / folder).glob("*.toml"))]  # fmt: skip
    assert len(shipped) == 7 and set(shipped) <= names
