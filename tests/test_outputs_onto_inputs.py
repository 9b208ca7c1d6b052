"""An output that is a file the command reads is refused before any work, however the two are
named: a shipped model found from another folder, a hard link, a run's trace onto its reference
file. One line, exit 2, the file untouched."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

import cartctl.choices
from cartctl.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], says: str) -> None:
    assert main(argv) == 2
    out, err = capsys.readouterr()
    (line,) = err.splitlines()
    assert out == "" and line.startswith(f"cartctl {argv[0]}: error: "), line
    assert says in line and "is a file this command reads" in line, line


def test_a_shipped_model_found_from_another_folder(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """design models/ground.toml from a folder without models/: the checkout's model is read, and
    --out naming it by its full path overwrote it with a controller."""
    checkout = tmp_path / "checkout"
    shutil.copytree(ROOT / "models", checkout / "models")
    monkeypatch.setattr(cartctl.choices, "_shipped_roots", lambda: (checkout,))
    monkeypatch.chdir(tmp_path)
    model = checkout / "models" / "ground.toml"
    before = model.read_bytes()
    argv = ["design", "models/ground.toml", "--method", "pi", "--out", str(model)]
    _refused(capsys, argv, f"--out {model}")
    _refused(capsys, ["tune", "models/ground.toml", "--method", "pi", "--choose", "1",
                      "--out", str(model)], "--out")  # fmt: skip
    excite = ["excite", "--amplitude", "5", "--cycles", "1"]  # the sim plant's default model
    _refused(capsys, [*excite, "--out", str(model)], "--out")
    assert model.read_bytes() == before


def test_excite_onto_its_sim_plants_model(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """excite --model M.toml --out M.toml replaced the model by the trace."""
    monkeypatch.chdir(tmp_path)
    shutil.copy(ROOT / "models" / "ground.toml", "m.toml")
    before = Path("m.toml").read_bytes()
    argv = ["excite", "--amplitude", "5", "--cycles", "1", "--model", "m.toml", "--out", "./m.toml"]
    _refused(capsys, argv, "--out ./m.toml")
    assert sorted(os.listdir()) == ["m.toml"] and Path("m.toml").read_bytes() == before


def test_a_hard_link_to_the_model(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)
    shutil.copy(ROOT / "models" / "ground.toml", "model.toml")
    before = Path("model.toml").read_bytes()
    os.link("model.toml", "link.toml")
    _refused(capsys, ["design", "model.toml", "--method", "pi", "--out", "link.toml"], "link.toml")
    assert Path("model.toml").read_bytes() == before


@pytest.mark.parametrize("option", ["--reference", "--reference-b"])
def test_a_run_onto_its_reference_file(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, option: str
) -> None:
    """run --reference file:ref.csv --name ref replaced the reference by the run's trace (and a
    run over a minute read its later references from that trace)."""
    monkeypatch.chdir(tmp_path)
    text = "time_s,reference\n0,0\n0.5,5\n"
    Path("ref.csv").write_text(text, encoding="utf-8")
    argv = ["run", "--fast", "--rerun", "off", "--duration", "0.2", option, "file:ref.csv",
            "--out", ".", "--name", "ref"]  # fmt: skip
    _refused(capsys, argv, "--out ref.csv")
    assert sorted(os.listdir()) == ["ref.csv"]
    assert Path("ref.csv").read_text(encoding="utf-8") == text
