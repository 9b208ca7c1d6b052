"""The superposition test: exact on the linear ARX plant, biased by Coulomb friction on the physics plant."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.data.trace import Trace, write_trace
from cartctl.errors import InputError
from cartctl.identification.validate import linearity
from cartctl.plants.physics import PhysicsPlant
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.loop import run_experiment
from cartctl.signals import step


def _steps(make_plant, amplitudes_v=(3.0, 7.0, 10.0), delays_s=(0.2, 0.3, 0.1)) -> list[Trace]:
    """Step experiments on motor a, with different onsets (the test must align them)."""
    traces = []
    for amp, delay in zip(amplitudes_v, delays_s, strict=True):
        u = step(amp, duration_s=1.5, delay_s=delay)
        trace = run_experiment(make_plant(), u, np.zeros_like(u), source=f"step{amp:g}.csv").trace
        traces.append(trace)
    return traces


@pytest.fixture
def arx_steps(ground_path: Path) -> list[Trace]:
    models = load_models(ground_path)
    return _steps(lambda: ArxPlant(models.motor("a"), models.motor("b")))


@pytest.fixture
def physics_steps() -> list[Trace]:
    return _steps(lambda: PhysicsPlant("ground"))


def test_linear_plant_superposes_exactly(arx_steps: list[Trace]) -> None:
    result = linearity(*arx_steps, motor="a")
    assert result.amplitudes_v == (3.0, 7.0, 10.0)
    assert result.onsets_s == pytest.approx((0.2, 0.3, 0.1))
    assert result.max_abs_error_rad_s < 1e-9
    assert abs(result.mean_error_rad_s) < 1e-9
    assert result.rms_error_percent == pytest.approx(0.0, abs=1e-9)
    # aligned over what all three cover: 1.5 s minus the latest onset
    assert len(result.time_s) == 150 - 30
    assert result.speed_sum_rad_s[-1] == pytest.approx(10.0 * 2.0202, rel=1e-3)


def test_coulomb_friction_makes_the_sum_step_run_above(physics_steps: list[Trace]) -> None:
    result = linearity(*physics_steps, motor="a")
    # The report: the 10 V response is higher than the 3 V and 7 V responses added, because each
    # step loses the friction once.
    assert result.mean_error_rad_s > 0.5
    assert result.mean_error_percent is not None and result.mean_error_percent > 3.0
    assert np.mean(result.error_rad_s[-50:]) > 0.5  # in steady state, not only in the transient
    np.testing.assert_allclose(
        result.error_rad_s, result.speed_sum_rad_s - result.speed_added_rad_s
    )
    d = result.to_dict()
    assert set(d["error_rad_s"]) == {"mean", "max_abs", "rms"}
    assert set(d["relative_percent"]) == {"rms", "mean"}
    assert d["amplitudes_v"] == {"small": 3.0, "large": 7.0, "sum": 10.0}


def test_amplitudes_that_do_not_add_up_are_named(arx_steps: list[Trace]) -> None:
    small, large, total = arx_steps
    with pytest.raises(InputError, match=r"3 V \+ 10 V = 13 V, but the sum step is 7 V"):
        linearity(small, total, large)


def test_amplitudes_within_tolerance_are_accepted(ground_path: Path) -> None:
    models = load_models(ground_path)
    traces = _steps(
        lambda: ArxPlant(models.motor("a"), models.motor("b")), amplitudes_v=(3.0, 7.0, 10.1)
    )
    assert linearity(*traces).amplitudes_v == (3.0, 7.0, 10.1)


def test_trace_without_a_step_is_refused(arx_steps: list[Trace]) -> None:
    with pytest.raises(InputError, match=r"motor b's voltage in step3\.csv is zero throughout"):
        linearity(*arx_steps, motor="b")


# -- the command line ----------------------------------------------------------------------------


def _write(traces: list[Trace], folder: Path) -> list[str]:
    paths = []
    for name, trace in zip(("step3.csv", "step7.csv", "step10.csv"), traces, strict=True):
        write_trace(trace, folder / name)
        paths.append(str(folder / name))
    return paths


def test_cli_json_and_plot(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, physics_steps: list[Trace]
) -> None:
    files = _write(physics_steps, tmp_path)
    png = tmp_path / "linearity.png"
    code = main(["linearity", *files, "--json", "--plot", str(png)])
    out, err = capsys.readouterr()
    assert code == 0 and err == ""
    doc = json.loads(out)
    assert doc["motor"] == "a" and doc["Ts"] == 0.01
    assert doc["data"] == {"small": files[0], "large": files[1], "sum": files[2]}
    assert doc["amplitudes_v"] == {"small": 3.0, "large": 7.0, "sum": 10.0}
    assert doc["error_rad_s"]["mean"] > 0.5
    assert doc["relative_percent"]["mean"] > 3.0
    assert png.stat().st_size > 10_000


def test_cli_text(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, arx_steps: list[Trace]
) -> None:
    code = main(["linearity", *_write(arx_steps, tmp_path)])
    out, _ = capsys.readouterr()
    assert code == 0
    assert "superposition test, motor a" in out and "rms" in out


def test_cli_bad_order_gives_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, arx_steps: list[Trace]
) -> None:
    small, large, total = _write(arx_steps, tmp_path)
    code = main(["linearity", small, total, large])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "do not add up" in err
