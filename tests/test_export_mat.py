"""``cartctl export --mat``: the shipped model and controllers as MATLAB files, read back with
scipy.io.loadmat and rebuilt as python-control objects the way :mod:`cartctl.export.mat` documents.

Expectations: the model file's own numbers read with tomllib, the PI law of the runtime docstring
computed by hand, and cartctl's runtime controllers (what the loop runs) for pole placement.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import control
import numpy as np
import pytest
import scipy.io

from cartctl.cli import main
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.export.arduino import as_steady_state

ROOT = Path(__file__).resolve().parents[1]
CONTROLLERS = ROOT / "controllers"
GROUND = ROOT / "models" / "ground.toml"


def _export(capsys: pytest.CaptureFixture[str], source: Path, target: Path) -> dict:
    code = main(["export", "--mat", str(target), str(source)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert out.startswith(f"wrote {target}")
    return scipy.io.loadmat(target, simplify_cells=True)


def _controller_ss(mat: dict, motor: str) -> control.StateSpace:
    a = mat[f"motor_{motor}"]
    return control.ss(*(np.atleast_2d(a[k]) for k in "ABCD"), mat["Ts"],
                      inputs=["r", "y"], outputs=["u"])  # fmt: skip


def test_model_exports_its_transfer_function(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    mat = _export(capsys, GROUND, tmp_path / "ground.mat")
    doc = tomllib.loads(GROUND.read_text(encoding="utf-8"))
    assert mat["Ts"] == doc["period_s"] == 0.01
    assert mat["format"] == doc["format"] == "cartctl-model/2"  # the shipped file's own version
    assert mat["source"] == str(GROUND)
    for motor in "ab":
        entry, got = doc["motors"][motor], mat[f"motor_{motor}"]
        c, d, a, b = entry["theta"]  # the report's (a z + b) / (z³ + c z² + d z)
        np.testing.assert_array_equal(got["theta"], entry["theta"])
        assert got["nk"] == entry["nk"] == 2 and got["Ts"] == 0.01
        assert np.size(got["theta_std"]) == 0  # the shipped file has none
        rebuilt = control.tf(got["num"], got["den"], mat["Ts"])
        expected = control.tf([a, b], [1.0, c, d, 0.0], 0.01)
        np.testing.assert_allclose(np.sort_complex(rebuilt.poles()),
                                   np.sort_complex(expected.poles()), atol=1e-12)  # fmt: skip
        np.testing.assert_allclose(np.sort_complex(rebuilt.zeros()),
                                   np.sort_complex(expected.zeros()), atol=1e-12)  # fmt: skip
        assert control.dcgain(rebuilt) == pytest.approx((a + b) / (1 + c + d), rel=1e-12)


@pytest.mark.parametrize("name", ["pi", "serial-pi"])
def test_pi_controller_steps_as_its_law_says(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, name: str
) -> None:
    mat = _export(capsys, CONTROLLERS / f"{name}.toml", tmp_path / f"{name}.mat")
    doc = tomllib.loads((CONTROLLERS / f"{name}.toml").read_text(encoding="utf-8"))
    assert mat["method"] == "pi" and mat["loop_delay_ticks"] == doc["loop_delay_ticks"]
    assert mat["format"] == doc["format"] == "cartctl-controller/2"
    assert mat["extra_delay_ticks"] == doc["request"]["extra_delay_ticks"]
    n = 50
    k = np.arange(n)
    for motor in "ab":
        kp, ki = doc["motors"][motor]["kp"], doc["motors"][motor]["ki"]
        assert mat[f"motor_{motor}"]["kp"] == kp and mat[f"motor_{motor}"]["ki"] == ki
        # a unit reference step with y = 0: e = 1, I[k] = Ki·Ts·(k + 1), u[k] = Kp + I[k]
        expected = kp + ki * 0.01 * (k + 1)
        ctrl = _controller_ss(mat, motor)
        u = control.forced_response(ctrl, T=k * 0.01, U=np.vstack([np.ones(n), np.zeros(n)])).y
        np.testing.assert_allclose(np.squeeze(u), expected, rtol=1e-12)
        # the measurement enters with the opposite sign: the feedback TF is the PI's C(z)
        fb = control.tf(mat[f"motor_{motor}"]["feedback_num"],
                        mat[f"motor_{motor}"]["feedback_den"], 0.01)  # fmt: skip
        for z in (0.5, 0.3 + 0.8j, -0.9):
            assert fb(z) == pytest.approx(kp + ki * 0.01 * z / (z - 1.0), rel=1e-12)


@pytest.mark.parametrize("name", ["poles", "serial-poles"])
def test_pole_placement_controller_runs_as_the_loop_runs_it(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, name: str
) -> None:
    mat = _export(capsys, CONTROLLERS / f"{name}.toml", tmp_path / f"{name}.mat")
    shipped = load_controller(CONTROLLERS / f"{name}.toml")
    # A, B, C, D are the controller with the steady-state gain L; with timing noise the loop's
    # gain moves after each command change and returns to L, so compare with the fixed gain
    runtime = build_controllers(as_steady_state(shipped))
    rng = np.random.default_rng(15)
    n = 300
    r, y = rng.normal(0.0, 2.0, n), rng.normal(0.0, 2.0, n)  # small: never saturates
    for motor in "ab":
        got = mat[f"motor_{motor}"]
        np.testing.assert_array_equal(got["K"], shipped.motors[motor]["K"])
        np.testing.assert_array_equal(got["L"], shipped.motors[motor]["estimator"]["L"])
        assert got["Kr"] == shipped.motors[motor]["Kr"]
        ctrl = _controller_ss(mat, motor)
        u = np.squeeze(control.forced_response(ctrl, T=np.arange(n) * 0.01, U=np.vstack([r, y])).y)
        loop = runtime[motor]
        loop.reset()
        expected = np.array([loop.step(r[k], y[k]) for k in range(n)])
        assert np.max(np.abs(expected)) < shipped.voltage_limit_v
        np.testing.assert_allclose(u, expected, atol=1e-9)


def test_arduino_and_mat_together(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    target, header = tmp_path / "pi.mat", tmp_path / "pi.h"
    argv = ["export", str(CONTROLLERS / "pi.toml"), "--arduino", "--out", str(header)]
    assert main([*argv, "--mat", str(target)]) == 0
    out = capsys.readouterr().out
    assert f"wrote {target}" in out and f"wrote {header}" in out
    assert "cartctl_step_a" in header.read_text(encoding="utf-8")
    assert scipy.io.loadmat(target)["method"] == "pi"


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--mat", "x.mat", str(ROOT / "pyproject.toml")], "neither a model file"),
        (["--arduino", str(GROUND)], "--arduino needs a controller file"),
        (["--mat", "x.mat", "nope.toml"], "not found"),
        ([str(GROUND)], "--mat FILE.mat"),
        (["--mat", "x.mat", "--out", "x.h", str(GROUND)], "--out"),
    ],
)
def test_wrong_files_and_options_are_one_line(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    argv: list[str],
    expected: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    code = main(["export", *argv])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and expected in err, err
    assert not (tmp_path / "x.mat").exists()


@pytest.mark.parametrize(
    ("shipped", "line", "replacement", "expected"),
    [
        ("poles.toml", "Ki = ", None, "misses Ki"),
        ("pi.toml", "ki = ", 'ki = "x"', "kp and ki must be numbers"),
        ("pi.toml", "anti_windup = ", 'anti_windup = "sometimes"', "anti-windup"),
    ],
)
def test_a_broken_controller_file_is_one_line_for_mat(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    shipped: str,
    line: str,
    replacement: str | None,
    expected: str,
) -> None:
    """--mat checks a controller file as the loop (and --arduino) do: no traceback, no file."""
    lines = (ROOT / "controllers" / shipped).read_text(encoding="utf-8").splitlines()
    motor_a = lines.index("[motors.a]")
    at = next(i for i, text in enumerate(lines) if i > motor_a and text.startswith(line))
    lines[at : at + 1] = [] if replacement is None else [replacement]
    broken = tmp_path / "broken.toml"
    broken.write_text("\n".join(lines) + "\n", encoding="utf-8")
    code = main(["export", str(broken), "--mat", str(tmp_path / "x.mat")])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and expected in err and str(broken) in err, err
    assert not (tmp_path / "x.mat").exists()
