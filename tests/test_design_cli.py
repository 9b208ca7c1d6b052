"""``cartctl design``: the JSON output checked independently, the shipped controllers, controller
files, and refused requests."""

from __future__ import annotations

import json
import math
import re
import tomllib
import warnings
from pathlib import Path

import control
import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.design.analysis import simulate_step
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.measures.stepinfo import step_info

ROOT = Path(__file__).resolve().parents[1]
CONTROLLERS = ROOT / "controllers"


def _design(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    code = main(["design", *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


@pytest.mark.parametrize(("pm", "fc", "extra"), [(60.0, 3.0, 0), (65.0, 4.4, 0), (50.0, 2.5, 2)])
def test_pi_margins_hold_when_checked_from_controller_num_den(
    capsys: pytest.CaptureFixture[str], ground_path: Path, pm: float, fc: float, extra: int
) -> None:
    doc = _design(capsys, str(ground_path), "--method", "pi", "--phase-margin", str(pm),
                  "--crossover-hz", str(fc), "--extra-delay", str(extra))  # fmt: skip
    assert doc["method"] == "pi"
    models = load_models(ground_path)
    for motor, entry in doc["motors"].items():
        model = models.motor(motor)
        c = control.tf(entry["controller_num"], entry["controller_den"], 0.01)
        g = control.tf(model.num(), model.den(), 0.01)
        delay = control.tf([1.0], [1.0] + [0.0] * extra, 0.01)
        _, pm_got, _, _, wcp, _ = control.stability_margins(c * g * delay, method="poly")
        assert pm_got == pytest.approx(pm, abs=1.0)
        assert wcp / (2 * math.pi) == pytest.approx(fc, rel=0.02)
        step = entry["step"]
        assert {"overshoot_percent", "settling_time_s", "rise_time_s"} <= set(step)
        assert entry["settling_bound_s"] > 0
        assert entry["settling_ratio"] >= 1.0


@pytest.mark.parametrize(
    ("poles", "more"),
    [("0.5+0.2j,0.5-0.2j,0.3", ()), ("0.5+0.2j,0.5-0.2j,0.3,0.1", ("--bias-drift-v", "0"))],
    ids=["disturbance-estimate", "error-integrator"],
)
def test_poles_are_placed_where_asked(
    capsys: pytest.CaptureFixture[str], ground_path: Path, poles: str, more: tuple[str, ...]
) -> None:
    asked = [complex(p) for p in poles.split(",")]
    doc = _design(capsys, str(ground_path), "--method", "poles", "--poles", poles, *more)
    for entry in doc["motors"].values():
        got = np.sort_complex([complex(re, im) for re, im in entry["closed_loop_poles"]])
        np.testing.assert_allclose(got, np.sort_complex(asked), atol=1e-6)
        assert len(entry["estimator_poles"]) >= 3
        assert all(abs(complex(*p)) < 1 for p in entry["estimator_poles"])
        # the linear feedback part closes the loop on the placed poles (separation principle)
        num, den = entry["controller_num"], entry["controller_den"]
        model = load_models(ground_path).motor("a")
        loop_poles = np.roots(
            np.polyadd(np.polymul(den, model.den()), np.polymul(num, model.num()))
        )
        for p in asked:
            assert np.min(np.abs(loop_poles - p)) < 1e-5
        break


@pytest.mark.parametrize("name", ["pi.toml", "poles.toml", "serial-pi.toml", "serial-poles.toml"])
def test_shipped_controllers_take_a_good_10_rad_s_step(name: str, ground_path: Path) -> None:
    shipped = load_controller(CONTROLLERS / name)
    timing = ground_path.parent / "ground-timing.toml"  # poles.toml's model
    model_path = timing if name == "poles.toml" else ground_path
    assert Path(shipped.model_path).resolve() == model_path.resolve()
    assert not shipped.model_changed()
    models = load_models(model_path)
    for motor, ctrl in build_controllers(shipped).items():
        # on the model and the extra delay it is designed for
        extra = int(shipped.request["extra_delay_ticks"])
        step = simulate_step(ctrl, models.motor(motor), step_rad_s=10.0, extra_delay_ticks=extra)
        assert step.info.overshoot_percent <= 5.0
        assert abs(step.info.steady_state_error) < 1e-6
        assert step.peak_voltage_v <= 12.0
        assert step.info.settling_time_s is not None
        assert shipped.motors[motor]["analysis"]["settling_ratio"] >= 1.0


@pytest.mark.parametrize("name", ["pi.toml", "serial-pi.toml"])
def test_shipped_pi_files_meet_their_request_by_python_control(name: str) -> None:
    """The file's Kp, Ki on its model (with its loop's delay): python-control's margins give the
    phase margin and crossover the file's request names."""
    import control

    shipped = load_controller(CONTROLLERS / name)
    models = load_models(Path(shipped.model_path))
    request = shipped.request
    for motor, entry in shipped.motors.items():
        model = models.motor(motor)
        extra = shipped.loop_delay_ticks - (model.nk - 1)
        plant = model.with_extra_delay(extra).to_tf()
        ts = shipped.period_s
        z = control.tf([1.0, 0.0], [1.0], ts)
        pi = entry["kp"] + entry["ki"] * ts * z / (z - 1)
        with warnings.catch_warnings():  # the integrator's pole at z = 1 on the way
            warnings.simplefilter("ignore", RuntimeWarning)
            _, pm, _, wc = control.margin(pi * plant)
        assert pm == pytest.approx(request["phase_margin_deg"], abs=0.05)
        assert wc / (2 * np.pi) == pytest.approx(request["crossover_hz"], rel=1e-3)


@pytest.mark.parametrize("name", ["poles.toml", "serial-poles.toml"])
def test_shipped_pole_placement_closes_the_loop_on_its_stored_poles(name: str) -> None:
    """The stored C(z) on the model (with the loop's delay), as a polynomial computation with
    numpy: the closed loop's roots include every stored pole of the state feedback."""
    shipped = load_controller(CONTROLLERS / name)
    models = load_models(Path(shipped.model_path))
    for motor, entry in shipped.motors.items():
        model = models.motor(motor)
        plant = model.with_extra_delay(int(shipped.request["extra_delay_ticks"]))
        num, den = entry["controller_num"], entry["controller_den"]
        roots = np.roots(np.polyadd(np.polymul(den, plant.den()), np.polymul(num, plant.num())))
        for re_, im in entry["closed_loop_poles"]:
            assert np.min(np.abs(roots - complex(re_, im))) < 1e-5


def test_controller_file_runs_what_was_designed(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path
) -> None:
    out = tmp_path / "c.toml"
    doc = _design(capsys, str(ground_path), "--method", "pi", "--estimator", "kalman",
                  "--out", str(out))  # fmt: skip
    loaded = build_controllers(load_controller(out))
    models = load_models(ground_path)
    for motor, ctrl in loaded.items():
        step = simulate_step(ctrl, models.motor(motor))
        assert step.info.overshoot_percent == pytest.approx(
            doc["motors"][motor]["step"]["overshoot_percent"]
        )
        assert step.peak_voltage_v == pytest.approx(doc["motors"][motor]["step"]["peak_voltage_v"])


@pytest.mark.parametrize("given", ["kalman", "time-varying", "steady-state"])
def test_an_old_files_estimator_gain_loads_with_the_fixed_gain(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path, given: str
) -> None:
    """``--estimator-gain`` is gone (a designed P is stationary: every name ran the same
    estimates); a file that still names one loads, and runs the fixed-gain filter."""
    with pytest.raises(SystemExit) as exc:
        main(["design", str(ground_path), "--method", "poles", "--estimator-gain", given])
    assert exc.value.code == 2
    assert "--estimator-gain" in capsys.readouterr().err
    out = tmp_path / "c.toml"
    _design(capsys, str(ground_path), "--method", "poles", "--measurement-noise", "0.05",
            "--out", str(out))  # fmt: skip
    request = load_controller(out).request
    assert "estimator_gain" not in request
    assert request["extra_noise_std_rad_s"] == 0.05  # beyond the quantisation: not the total √R
    assert "measurement_noise_std_rad_s" not in request
    text = out.read_text(encoding="utf-8").replace(
        "[request]\n", f'[request]\nestimator_gain = "{given}"\n'
    )
    out.write_text(text, encoding="utf-8")
    assert load_controller(out).request["estimator_gain"] == given
    estimators = {
        type(c.estimator).__name__ for c in build_controllers(load_controller(out)).values()
    }
    assert estimators == {"SteadyStateSpeedEstimator"}


def test_report_writes_a_figure_per_motor(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path
) -> None:
    import matplotlib.image

    assert main(["design", str(ground_path), "--method", "poles", "--motor", "a", "--report",
                 str(tmp_path)]) == 0  # fmt: skip
    capsys.readouterr()
    image = matplotlib.image.imread(tmp_path / "design_a.png")
    assert image.shape[0] > 500
    assert not (tmp_path / "design_b.png").exists()  # the motor not asked for


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--method", "poles", "--poles", "1.2,0.5,0.3"], "unit circle"),
        (["--method", "poles", "--poles", "0.5,0.3"], "needs 3 closed-loop poles"),
        (["--method", "poles", "--poles", "0.5,0.3,0.2", "--bias-drift-v", "0"], "needs 4"),
        (["--method", "poles", "--bias-drift-v", "-0.1"], "--bias-drift-v"),
        (["--method", "poles", "--poles", "0.5,zz"], "not a number"),
        (["--method", "pi", "--phase-margin", "120"], "--phase-margin"),
        (["--method", "pi", "--crossover-hz", "80"], "Nyquist"),
        (["--method", "pi", "--voltage-limit", "15"], "--voltage-limit"),
        (["--method", "pi", "--extra-delay", "-1"], "--extra-delay"),
    ],
)
def test_impossible_requests_give_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], ground_path: Path, argv: list[str], message: str
) -> None:
    code = main(["design", str(ground_path), *argv])
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_missing_model_file(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["design", "nope.toml", "--method", "pi"])
    _, err = capsys.readouterr()
    assert code == 2
    assert "model file not found: nope.toml" in err


def test_settling_bound_and_ratio_are_for_the_designs_loop_and_band(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path
) -> None:
    """The bound is on the model with the extra delay (one tick later per tick of delay) and the
    step's settling is measured in the same band, max(2 %, one encoder count = 0.3506 rad/s)."""
    quantum = 2 * math.pi / 1792 / 0.01
    docs = {}
    for extra in (0, 3):
        out = tmp_path / f"pi{extra}.toml"
        docs[extra] = _design(capsys, str(ground_path), "--method", "pi", "--phase-margin", "65",
                              "--crossover-hz", "3", "--extra-delay", str(extra), "--out", str(out))  # fmt: skip
        models = load_models(ground_path)
        for motor, ctrl in build_controllers(load_controller(out)).items():
            entry = docs[extra]["motors"][motor]
            assert entry["settling_bound_loop_delay_ticks"] == 1 + extra  # nk = 2: 1 + d
            step = simulate_step(
                ctrl, models.motor(motor), step_rad_s=10.0, extra_delay_ticks=extra
            )
            info = step_info(step.time_s, step.speed_rad_s, reference=10.0,
                             settling_band=quantum / 10.0)  # fmt: skip
            assert entry["step"]["settling_time_s"] == pytest.approx(info.settling_time_s)
            assert entry["settling_ratio"] == pytest.approx(
                info.settling_time_s / entry["settling_bound_s"]
            )
            assert entry["settling_ratio"] >= 1.0
    for motor in ("a", "b"):
        delta = (
            docs[3]["motors"][motor]["settling_bound_s"]
            - docs[0]["motors"][motor]["settling_bound_s"]
        )
        assert delta == pytest.approx(0.03)  # three ticks
    assert main(["design", str(ground_path), "--method", "pi", "--phase-margin", "65",
                 "--crossover-hz", "3", "--extra-delay", "3"]) == 0  # fmt: skip
    text = capsys.readouterr().out
    assert (
        text.count("fastest settling within the voltage limit for a loop delay of 4 tick(s)") == 2
    )


def test_a_design_on_a_shipped_model_from_another_folder_runs_without_a_changed_model(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """In a folder without models/, 'models/ground.toml' is the shipped file: design hashes it,
    the controller keeps its shipped name, and a run of that controller finds it unchanged."""
    monkeypatch.chdir(tmp_path)
    assert main(["design", "models/ground.toml", "--method", "pi", "--out", "c/g.toml"]) == 0
    capsys.readouterr()
    doc = tomllib.loads((tmp_path / "c" / "g.toml").read_text())
    assert doc["model"]["path"] == "models/ground.toml"
    code = main(["run", "--fast", "--controller", "c/g.toml", "--duration", "0.3", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "changed" not in err
    assert json.loads(out)["ticks"] > 0


def test_the_settling_bound_names_the_loop_the_design_is_for(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """models/ground-timing.toml: nk = 1, recorded in a loop of 1 tick. The design is for loop
    delay 1 (the file's loop_delay_ticks), and so is the bound it is compared with."""
    timing = ROOT / "models" / "ground-timing.toml"
    assert load_models(timing).motor("a").nk == 1
    doc = _design(capsys, str(timing), "--method", "poles")
    for motor in ("a", "b"):
        assert doc["motors"][motor]["settling_bound_loop_delay_ticks"] == 1


def test_pole_placement_from_the_specification_on_a_first_order_model(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """na = nb = nk = 1 in a loop of 1 tick: one state, one placed pole. The default settling
    time and overshoot were refused ('needs 1 closed-loop poles, got 2': the dominant pair); the
    one pole is the pair's decay exp(−4 Ts / 0.06 s), and the loop (the file's controller_num/den
    on the model, with the estimator's poles) closes on it."""
    path = tmp_path / "first.toml"
    path.write_text(
        'format = "cartctl-model/2"\nperiod_s = 0.01\nloop_delay_ticks = 1\n\n[provenance]\n'
        'source = "t"\ncreated = "2026-01-01"\ndata = []\nmethod = "arx"\nprefilter = "none"\n'
        'notes = ""\n\n[motors.a]\ntheta = [-0.9, 0.2]\nna = 1\nnb = 1\nnk = 1\n'
    )
    entry = _design(capsys, str(path), "--method", "poles", "--motor", "a", "--step", "5")
    entry = entry["motors"]["a"]
    pole = math.exp(-4.0 * 0.01 / 0.06)
    np.testing.assert_allclose(entry["closed_loop_poles"], [[pole, 0.0]], atol=1e-12)
    expected = [complex(re, im) for re, im in entry["closed_loop_poles"] + entry["estimator_poles"]]
    num, den = entry["controller_num"], entry["controller_den"]
    model = load_models(path).motor("a")
    loop = np.roots(np.polyadd(np.polymul(den, model.den()), np.polymul(num, model.num())))
    for p in expected:
        assert np.min(np.abs(loop - p)) < 1e-6
    assert entry["step"]["overshoot_percent"] <= 1.0


def test_a_refused_bandwidth_names_a_range_whose_ends_can_be_asked_for(
    capsys: pytest.CaptureFixture[str], ground_path: Path
) -> None:
    """Motor a of models/ground.toml at 65°: 4.003 Hz to 21.785 Hz. The refusal of 4 Hz said 'it
    gives 4.00 Hz to 21.79 Hz', two values it refused too; the ends are now rounded inwards."""
    argv = [str(ground_path), "--method", "pi", "--motor", "a", "--json"]
    assert main(["design", *argv, "--bandwidth-hz", "4"]) == 2
    err = capsys.readouterr().err
    ends = re.search(r"it gives ([\d.]+) Hz to ([\d.]+) Hz", err)
    assert ends, err
    for end in ends.groups():
        doc = _design(capsys, *argv[:-1], "--bandwidth-hz", end)
        assert doc["motors"]["a"]["bandwidth_hz"] == pytest.approx(float(end), rel=1e-6)
