"""A model without an input delay (nk = 0, which ``identify --delay 0`` fits and writes): every
command that would design on it or run it as a plant refuses it with one and the same line, exit
code 2, before any work (``tune --method poles`` used to report every grid setting infeasible and
exit 0)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

import cartctl
from cartctl.cli import main
from cartctl.data.modelfile import ModelFile, load_models, save_models
from cartctl.errors import InputError


@pytest.fixture
def nk0_path(tmp_path: Path, ground_path: Path) -> Path:
    ground = load_models(ground_path)
    models = {m: dataclasses.replace(ground.motor(m), nk=0) for m in ("a", "b")}
    return save_models(ModelFile(models, ground.provenance), tmp_path / "nk0.toml")


def test_one_refusal_for_nk_zero(
    capsys: pytest.CaptureFixture[str], nk0_path: Path, tmp_path: Path
) -> None:
    model = str(nk0_path)
    sim = ["--plant", "sim", "--model", model]
    commands = [
        ["design", model, "--method", "pi"],
        ["design", model, "--method", "poles"],
        ["tune", model, "--method", "pi", "--duration", "0.5", "--jobs", "1"],
        ["tune", model, "--method", "poles", "--duration", "0.5", "--jobs", "1"],
        ["excite", *sim, "--amplitude", "5", "--out", str(tmp_path / "x.csv")],
        ["run", *sim, "--fast", "--duration", "0.5", "--rerun", "off", "--out", str(tmp_path)],
    ]
    reasons = set()
    for argv in commands:
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2, (argv, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1, (argv, err)
        reasons.add(lines[0].split(": error: ", 1)[1].removeprefix(f"{model}: "))
    for design in (cartctl.design_pi, cartctl.design_poles):
        with pytest.raises(InputError) as refused:
            design(cartctl.load_model(nk0_path))
        reasons.add(str(refused.value).removeprefix(f"{model}: "))
    assert len(reasons) == 1, reasons
    assert "nk = 0" in reasons.pop()


def test_identify_says_design_refuses_nk_zero(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    trace = str(tmp_path / "sq.csv")
    assert (
        main(["excite", "--plant", "sim", "--amplitude", "6", "--cycles", "2", "--out", trace]) == 0
    )
    assert main(["identify", trace, "--delay", "0"]) == 0
    assert "nk = 0: design, tune and the sim plant refuse it" in capsys.readouterr().out
