"""The shipped model and controller files from any folder, and in the wheel a plain install gets.

``controllers/pi.toml`` names the working folder's file when there is one, else the one shipped
with cartctl (``cartctl.choices.find_file``): in this editable install, the checkout's.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

from cartctl import choices
from cartctl.choices import SHIPPED_FILES, SHIPPED_FOLDERS, find_file
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


def _tracked(folder: str) -> set[str]:
    """The files of ``folder`` that git tracks; in a copy without git (CI's), the folder's files."""
    listed = subprocess.run(["git", "ls-files", folder], capture_output=True, text=True, cwd=ROOT)
    if listed.returncode == 0 and (ROOT / ".git").exists():
        return {Path(line).name for line in listed.stdout.splitlines()}
    return {path.name for path in (ROOT / folder).iterdir() if path.is_file()}


def test_the_shipped_list_names_the_files_git_tracks() -> None:
    """A newly shipped model or controller cannot be forgotten in the list the wheel packs."""
    assert set(SHIPPED_FILES) == set(SHIPPED_FOLDERS) == {"models", "controllers"}
    for folder, names in SHIPPED_FILES.items():
        assert set(names) == _tracked(folder), folder
        assert len(set(names)) == len(names)


def test_find_file_finds_only_shipped_names_outside_the_working_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A user's file beside the shipped ones (an editable checkout's models/mine.toml) is not
    found from another folder: the same answer as in a wheel, which never has it."""
    install = tmp_path / "install"
    for relative in ("models/ground.toml", "models/mine.toml", "controllers/mine2.toml"):
        (install / relative).parent.mkdir(parents=True, exist_ok=True)
        (install / relative).write_text("", encoding="utf-8")
    monkeypatch.setattr(choices, "_shipped_roots", lambda: (install,))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert find_file("models/ground.toml") == install / "models" / "ground.toml"
    assert find_file("./models/ground.toml") == install / "models" / "ground.toml"
    for given in ("models/mine.toml", "controllers/mine2.toml", "models/x/ground.toml"):
        assert find_file(given) == Path(given)


def _source_copy(tmp_path: Path) -> Path:
    """The sources a build sees, with a user's own model and controller beside the shipped."""
    source = tmp_path / "source"  # a copy: building writes build/ next to the sources
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "build")
    source.mkdir()
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy2(ROOT / name, source / name)
    for folder in ("src", "models", "controllers"):
        shutil.copytree(ROOT / folder, source / folder, ignore=ignore)
    shutil.copy2(source / "models" / "ground.toml", source / "models" / "mine.toml")
    shutil.copy2(source / "controllers" / "pi.toml", source / "controllers" / "mine2.toml")
    return source


EXPECTED = {f"{folder}/{name}" for folder, names in SHIPPED_FILES.items() for name in names}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """pip's own build of a wheel, with a user's model and controller beside the shipped ones."""
    tmp_path = tmp_path_factory.mktemp("wheel")
    source = _source_copy(tmp_path)
    out = tmp_path / "wheel"
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "-q", "-w", str(out)],
        capture_output=True, text=True, cwd=tmp_path,
    )  # fmt: skip
    assert built.returncode == 0, built.stderr
    (path,) = out.glob("cartctl-*.whl")
    return path


def test_the_wheel_ships_only_cartctl_files(wheel: Path) -> None:
    prefix = "cartctl/shipped/"
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
    assert {n.removeprefix(prefix) for n in names if n.startswith(prefix)} == EXPECTED
    assert not [n for n in names if "mine" in n]  # not models/mine.toml nor controllers/mine2.toml


def test_the_installed_package_finds_its_shipped_files_from_any_folder(
    wheel: Path, tmp_path: Path
) -> None:
    """The wheel unpacked into a folder, as an install puts it, and that folder first on the
    path, from a folder without models/ or controllers/."""
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as archive:
        archive.extractall(site)
    shipped = site / "cartctl" / "shipped"
    assert {p.relative_to(shipped).as_posix() for p in shipped.rglob("*.toml")} == EXPECTED
    code = (
        "import cartctl, json; from cartctl.choices import find_file; "
        "from cartctl.design.controllerfile import load_controller; "
        "c = load_controller('controllers/poles.toml'); "
        "print(json.dumps([cartctl.__file__, str(find_file('models/ground.toml')), "
        "str(c.path), c.model_path, str(find_file('models/mine.toml'))]))"
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    ran = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=elsewhere, env={**os.environ, "PYTHONPATH": str(site)})  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    package, ground, poles, poles_model, mine = json.loads(ran.stdout)
    site = site.resolve()
    assert Path(package).resolve().is_relative_to(site)
    assert Path(ground).resolve() == site / "cartctl" / "shipped" / "models" / "ground.toml"
    assert Path(poles).resolve() == site / "cartctl" / "shipped" / "controllers" / "poles.toml"
    assert Path(poles_model).resolve() == site / "cartctl/shipped/models/ground-timing.toml"
    assert mine == "models/mine.toml"  # a user's name is never looked up in the package


def test_the_sdist_carries_only_cartctl_files(tmp_path: Path) -> None:
    """A wheel built from the sdist (``python -m build``'s path) has the shipped files too."""
    source = _source_copy(tmp_path)
    code = "from setuptools import build_meta; print(build_meta.build_sdist('dist'))"
    built = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           cwd=source)  # fmt: skip
    assert built.returncode == 0, built.stderr
    name = built.stdout.strip().splitlines()[-1]
    with tarfile.open(source / "dist" / name) as archive:
        members = [m.split("/", 1)[1] for m in archive.getnames() if "/" in m]
    assert {m for m in members if m.startswith(("models/", "controllers/"))} == EXPECTED
