"""``cartctl inspect`` flags non-minimum-phase zeros; the linearity figure's legends leave the
error trace visible."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.data.trace import write_trace
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.loop import run_experiment
from cartctl.signals import step

# Motor a: the ground model's poles with b = (0.2, 0.5): zero at −0.5 / 0.2 = −2.5, as an ARX fit
# of the physics preset has. Motor b: the ground model's own (zero at 0.12).
MODEL = """format = "cartctl-model/1"
period_s = 0.01

[provenance]
source = "test"
created = "2026-01-01"
data = []
method = "arx"
prefilter = "none"
notes = ""

[motors.a]
theta = [-0.9356, 0.2173, 0.2, 0.5]
na = 2
nb = 2
nk = 1

[motors.b]
theta = [-0.9082, 0.1968, 0.6886, -0.1068]
na = 2
nb = 2
nk = 2
"""


def _inspect(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    code = main(["inspect", *argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


def test_a_zero_outside_the_unit_circle_is_flagged(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "nmp.toml"
    path.write_text(MODEL)
    zero = np.roots([0.2, 0.5])  # independent: the numerator's root
    assert abs(zero[0]) > 1.0
    doc = json.loads(_inspect(capsys, str(path), "--json"))
    assert doc["motors"]["a"]["minimum_phase"] is False
    assert doc["motors"]["b"]["minimum_phase"] is True
    zeros = [complex(z["re"], z["im"]) for z in doc["motors"]["a"]["zeros"]]
    assert zeros == pytest.approx(list(zero))
    text = _inspect(capsys, str(path))
    row = next(ln for ln in text.splitlines() if ln.split()[:2] == ["zero", "-2.5000"])
    assert "non-minimum-phase" in row
    assert "NOT minimum phase: zero outside the unit circle at z = -2.5000" in text
    assert text.count("NOT minimum phase") == 1


def test_the_shipped_ground_model_is_minimum_phase(
    capsys: pytest.CaptureFixture[str], ground_path: Path
) -> None:
    doc = json.loads(_inspect(capsys, str(ground_path), "--json"))
    for motor, model in load_models(ground_path).motors.items():
        expected = bool(np.all(np.abs(np.roots(model.b)) <= 1.0))
        assert expected
        assert doc["motors"][motor]["minimum_phase"] is expected
    text = _inspect(capsys, str(ground_path))
    assert text.count(", minimum phase") == 2 and "non-minimum-phase zero" not in text


def test_linearity_legends_sit_beside_the_panels(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path
) -> None:
    models = load_models(ground_path)
    files = []
    for amp in (3.0, 7.0, 10.0):
        u = step(amp, duration_s=1.0, delay_s=0.1)
        plant = ArxPlant(models.motor("a"), models.motor("b"))
        trace = run_experiment(plant, u, np.zeros_like(u), source=f"s{amp:g}.csv").trace
        write_trace(trace, tmp_path / f"s{amp:g}.csv")
        files.append(str(tmp_path / f"s{amp:g}.csv"))
    png = tmp_path / "lin.png"
    assert main(["linearity", *files, "--plot", str(png)]) == 0
    capsys.readouterr()
    assert png.read_bytes()[:4] == b"\x89PNG"
    # the figure the command drew: no legend overlaps any panel's data area
    from cartctl.cli.commands.linearity import linearity_figure
    from cartctl.data.read import read_trace
    from cartctl.identification.validate import linearity

    fig = linearity_figure(linearity(*(read_trace(f) for f in files), "a"))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legends = [ax.get_legend() for ax in fig.axes]
    assert all(leg is not None for leg in legends)
    for leg in legends:
        box = leg.get_window_extent(renderer)
        for ax in fig.axes:
            assert not box.overlaps(ax.get_window_extent(renderer))
        assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1)
