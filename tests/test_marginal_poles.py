"""Poles on the unit circle: a simple one (an integrator at z = 1, an undamped oscillation) is
marginally stable, a repeated one or one outside is unstable (``ArxModel.stability``); ``inspect``
and ``design`` say so in those words (both called an integrator UNSTABLE / unstable)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.model import ArxModel

GROUND_B = "[-0.9082, 0.1968, 0.6886, -0.1068]"


def _model(tmp_path: Path, poles: list[complex]) -> Path:
    """A model file whose motor a has the poles ``poles`` (na = len(poles)), motor b ground's."""
    ar = [float(v) for v in np.real(np.poly(poles))[1:]]
    path = tmp_path / "m.toml"
    path.write_text(
        'format = "cartctl-model/2"\nperiod_s = 0.01\n\n[provenance]\nsource = "test"\n'
        f'created = "2026-11-26"\n\n[motors.a]\ntheta = {[*ar, 0.6466, -0.07751]!r}\n'
        f"na = {len(ar)}\nnb = 2\nnk = 2\n\n[motors.b]\ntheta = {GROUND_B}\nna = 2\nnb = 2\nnk = 2\n"
    )
    return path


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


ON_CIRCLE = np.exp(0.3j)
CASES = [  # motor a's poles, its stability
    ([1.0, 0.5], "marginally stable"),  # an integrator
    ([ON_CIRCLE, ON_CIRCLE.conjugate()], "marginally stable"),  # an undamped oscillation
    ([-1.0, 0.5], "marginally stable"),
    ([1.0, 1.0], "unstable"),  # a double integrator: its step response grows as k²
    ([1.2, 0.5], "unstable"),
    ([0.995, 0.5], "stable"),
]


@pytest.mark.parametrize(("poles", "expected"), CASES)
def test_stability_of_poles_on_and_off_the_unit_circle(poles: list[complex], expected: str) -> None:
    model = ArxModel.from_theta([*np.real(np.poly(poles))[1:], 0.6466, -0.07751], nk=2)
    assert model.stability() == expected
    assert model.is_stable() is (expected == "stable")  # is_stable: every pole inside


@pytest.mark.parametrize(("poles", "expected"), CASES)
def test_inspect_says_marginally_stable_on_the_unit_circle(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, poles: list[complex], expected: str
) -> None:
    path = _model(tmp_path, poles)
    code, out, err = _cli(capsys, "inspect", str(path))
    assert code == 0, err
    block_a = out.split("motor b:")[0]
    summary = next(line for line in block_a.splitlines() if "DC gain" in line)
    flags = [line for line in block_a.splitlines() if line.lstrip().startswith("pole ")]
    if expected == "marginally stable":
        assert "MARGINALLY STABLE" in summary and "UNSTABLE" not in summary
        assert any("on the unit circle" in line for line in flags)
    elif expected == "unstable":
        assert "UNSTABLE" in summary
        assert all("slow or marginal" not in line for line in flags if "1.2000" in line)
    else:
        assert ", stable but SLOW OR MARGINAL" in summary
    code, out, err = _cli(capsys, "inspect", str(path), "--json")
    assert code == 0, err
    assert json.loads(out)["motors"]["a"]["stable"] is (expected == "stable")  # as before


def test_design_says_marginally_stable_for_an_integrator(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = _model(tmp_path, [1.0, 0.5])
    for method in ("pi", "poles"):
        code, out, err = _cli(capsys, "design", str(path), "--method", method,
                              "--out", str(tmp_path / "c.toml"))  # fmt: skip
        assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
        assert "marginally stable" in err and "is unstable" not in err
        assert not (tmp_path / "c.toml").exists()


def test_validate_names_a_marginal_model_so(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """validate said 'unstable' of an integrator, as inspect and design no longer do."""
    data = tmp_path / "sq.csv"
    code, _, _ = _cli(capsys, "excite", "--plant", "sim", "--signal", "square", "--amplitude",
                      "6", "--out", str(data))  # fmt: skip
    assert code == 0
    for poles, word in (([1.0, 0.5], "marginally stable"), ([2.0, 0.5], "unstable")):
        code, out, err = _cli(capsys, "validate", str(_model(tmp_path, poles)), str(data))
        assert f"motor a's model is {word} (pole at |z| = {max(np.abs(poles)):.4g})" in err
        assert f"motor a: the model is {word} (pole at" in out
