"""Model validation: a model on its own data is perfect; on the physical simulator it is plausible."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cart import encoder_quantum_rad_s
from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.data.trace import Trace, write_trace
from cartctl.errors import InputError
from cartctl.identification.validate import validate, validate_models
from cartctl.measures.stepinfo import step_info
from cartctl.plants.physics import PhysicsPlant
from cartctl.plants.sim import ArxPlant
from cartctl.runtime.loop import run_experiment
from cartctl.signals import square, step


def _step_a(plant: object, amplitude_v: float = 10.0) -> Trace:
    u = step(amplitude_v, duration_s=2.0, delay_s=0.2)
    return run_experiment(plant, u, np.zeros_like(u), source="step.csv").trace


@pytest.fixture
def ground(ground_path: Path):
    return load_models(ground_path)


@pytest.fixture
def sim_step(ground) -> Trace:
    return _step_a(ArxPlant(ground.motor("a"), ground.motor("b")))


@pytest.fixture
def physics_step() -> Trace:
    return _step_a(PhysicsPlant("ground"))


def test_model_on_its_own_data_fits_perfectly(ground, sim_step: Trace) -> None:
    result = validate(ground.motor("a"), sim_step, "a")
    assert result.fit_simulation_percent == pytest.approx(100.0, abs=1e-9)
    assert result.error_summary()["max"] == pytest.approx(0.0, abs=1e-9)
    step_cmp = result.step
    assert step_cmp is not None
    assert step_cmp.amplitude_v == 10.0
    assert step_cmp.onset_s == pytest.approx(0.2)
    measured, simulated = step_cmp.measured.to_dict(), step_cmp.simulated.to_dict()
    assert measured == pytest.approx(simulated, abs=1e-9)
    assert step_cmp.steady_state_error_rad_s == pytest.approx(0.0, abs=1e-9)
    # DC gain (0.6466 − 0.07751) / (1 − 0.9356 + 0.2173) = 2.02 rad/s/V
    assert step_cmp.simulated.steady_state_value == pytest.approx(20.2, abs=0.05)


def test_physics_step_fits_plausibly(ground, physics_step: Trace) -> None:
    result = validate(ground.motor("a"), physics_step, "a")
    assert 70.0 < result.fit_simulation_percent < 100.0
    assert result.step is not None
    m, s = result.step.measured, result.step.simulated
    assert m.rise_time_s is not None and s.rise_time_s is not None
    assert m.rise_time_s == pytest.approx(s.rise_time_s, abs=0.02)
    assert m.steady_state_value == pytest.approx(s.steady_state_value, rel=0.05)
    d = result.to_dict()
    assert set(d) == {"fit_simulation_percent", "abs_error", "step", "stable"}
    assert d["stable"] is True
    assert set(d["abs_error"]) == {"max", "mean", "rms"}


def test_non_step_input_has_no_step_metrics(ground) -> None:
    u = square(10.0, cycles=1)
    trace = run_experiment(ArxPlant(ground.motor("a"), ground.motor("b")), u, u).trace
    result = validate(ground.motor("b"), trace, "b")
    assert result.step is None
    assert result.to_dict()["step"] is None
    assert result.fit_simulation_percent == pytest.approx(100.0)


def test_trace_that_starts_at_the_step(ground) -> None:
    u = np.full(150, 6.0)
    trace = run_experiment(ArxPlant(ground.motor("a"), ground.motor("b")), u, u).trace
    result = validate(ground.motor("a"), trace, "a")
    assert result.step is not None
    assert result.step.onset_s == 0.0
    assert result.step.amplitude_v == 6.0


def test_idle_motor_is_refused_with_the_other_one_suggested(ground, sim_step: Trace) -> None:
    with pytest.raises(
        InputError, match=r"motor b's voltage is zero throughout step\.csv.*--motor a"
    ):
        validate(ground.motor("b"), sim_step, "b")


def test_validate_models_skips_idle_motors_when_asked(ground, sim_step: Trace) -> None:
    both = validate_models(ground, sim_step, ("a", "b"), skip_idle=True)
    assert list(both.results) == ["a"]
    assert both.skipped == ("b",)
    d = both.to_dict()
    assert d["Ts"] == 0.01 and d["data"] == "step.csv" and d["model"].endswith("ground.toml")
    with pytest.raises(InputError, match="zero throughout"):
        validate_models(ground, sim_step, ("a", "b"))


def test_trace_at_another_period_is_refused(ground, sim_step: Trace) -> None:
    columns = sim_step.columns() | {"time_s": sim_step.time_s * 2.0}
    slow = Trace.from_columns(columns, source="slow.csv")
    with pytest.raises(InputError, match="20 ms"):
        validate(ground.motor("a"), slow, "a")


# -- the command line ----------------------------------------------------------------------------


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_json(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path, physics_step: Trace
) -> None:
    data = tmp_path / "step10.csv"
    write_trace(physics_step, data)
    code, out, err = _cli(capsys, "validate", str(ground_path), str(data), "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["Ts"] == 0.01
    assert doc["data"] == str(data) and doc["model"] == str(ground_path)
    assert list(doc["motors"]) == ["a"]  # b is idle and skipped under the default --motor both
    assert "motor b" in err and "skipped" in err
    a = doc["motors"]["a"]
    assert 70.0 < a["fit_simulation_percent"] < 100.0
    assert set(a["abs_error"]) == {"max", "mean", "rms"}
    assert set(a["step"]) >= {"measured", "simulated"}
    assert a["step"]["measured"]["rise_time_s"] > 0.0


def test_cli_table_and_plot(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path, sim_step: Trace
) -> None:
    data = tmp_path / "step.csv"
    write_trace(sim_step, data)
    png = tmp_path / "figs" / "validate.png"
    code, out, _ = _cli(
        capsys, "validate", str(ground_path), str(data), "--motor", "a", "--plot", str(png)
    )
    assert code == 0
    assert "fit 100.00 %" in out and "rise time" in out
    assert png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--motor", "b"], "motor b's voltage is zero throughout"),
        (["--plot", "figure.jpg"], ".png"),
    ],
)
def test_cli_user_mistakes_give_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    ground_path: Path,
    sim_step: Trace,
    extra: list[str],
    message: str,
) -> None:
    data = tmp_path / "step.csv"
    write_trace(sim_step, data)
    code, out, err = _cli(capsys, "validate", str(ground_path), str(data), *extra)
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and message in err


def test_cli_missing_data_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path
) -> None:
    code, _, err = _cli(capsys, "validate", str(ground_path), str(tmp_path / "nope.csv"))
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "not found" in err


def test_an_unstable_model_has_one_fit_in_validate_and_identify(sim_step: Trace) -> None:
    """One answer for an unstable model on both paths: −inf (worse than any model, null in JSON),
    whether its simulation overflows within the data or stays finite over it."""
    from cartctl.identification.arx import simulation_fit
    from cartctl.model import ArxModel

    u, y = sim_step.voltage("a"), sim_step.speed("a")
    slow = ArxModel.from_theta([-1.05, 0.0, 0.1, 0.0])  # a pole at 1.05: finite over 2.2 s
    wild = ArxModel.from_theta([-1000.0, 0.0, 0.1, 0.0])  # a pole at 1000: overflows
    assert np.isfinite(slow.simulate(u)).all()
    for model in (slow, wild):
        assert simulation_fit(model, [(y, u)]) == -np.inf  # identify, its orders and delays
        result = validate(model, sim_step, "a")
        assert result.fit_simulation_percent == -np.inf
        assert result.to_dict()["fit_simulation_percent"] is None
        assert result.to_dict()["stable"] is False


@pytest.mark.parametrize("amplitude_v", [1.0, 2.0, 4.0])
def test_step_settles_in_the_band_run_and_review_use(air_path: Path, amplitude_v: float) -> None:
    # a small step on the physics plant: 2 % of it is narrower than one encoder count per tick,
    # so a bare 2 % band judged the quantisation (settled after seconds, or never)
    trace = _step_a(PhysicsPlant("air"), amplitude_v)
    result = validate(load_models(air_path).motor("a"), trace, "a")
    assert result.step is not None
    band = {"settling_floor": encoder_quantum_rad_s(trace.period_s), "onset_s": 0.2}
    for info, speed in ((result.step.measured, trace.speed("a")),
                        (result.step.simulated, result.simulated_rad_s)):  # fmt: skip
        assert info.settling_time_s == pytest.approx(
            step_info(trace.time_s, speed, **band).settling_time_s
        )
    settled = result.step.measured.settling_time_s
    assert settled is not None and settled < 0.3
