"""Timing noise in the estimator (``design --timing-noise-ticks``) and a loop delay apart from the
model's (``design --loop-delay``): the runtime filter against a hand-written Kalman filter, old
files unchanged, the refusals, the exports and the batch loop."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.design.controllerfile import build_controllers, load_controller, make_estimator
from cartctl.design.kalman import design_kalman
from cartctl.design.request import DesignRequest
from cartctl.errors import InputError
from cartctl.runtime.kalman import KalmanSpeedEstimator, SteadyStateSpeedEstimator

ROOT = Path(__file__).resolve().parents[1]
TIMING_MODEL = ROOT / "models" / "ground-timing.toml"


def hand_filter(design, sigma: float, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x̂_1[k|k] of a Kalman filter written out here: correct with y[k], then predict with u[k]
    and Q[k] = Q + (σ (u[k] − u[k−1]))² B Bᵀ (u[−1] = 0), from x̂ = 0 and the design's P."""
    A, B, C = (np.array(getattr(design, k), dtype=float) for k in "ABC")
    Q, R = np.array(design.Q, dtype=float), float(design.R)
    x, P, previous = np.zeros(A.shape[0]), np.array(design.P, dtype=float), 0.0
    out = []
    for uk, yk in zip(u, y, strict=True):
        gain = P @ C / (C @ P @ C + R)
        x = x + gain * (yk - C @ x)
        P = P - np.outer(gain, C @ P)
        out.append(x[0])
        x = A @ x + B * uk
        P = A @ P @ A.T + Q + (sigma * (uk - previous)) ** 2 * np.outer(B, B)
        previous = uk
    return np.array(out)


def run_estimator(estimator, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    out = []
    for uk, yk in zip(u, y, strict=True):
        out.append(estimator.correct(float(yk)))
        estimator.predict(float(uk))
    return np.array(out)


@pytest.fixture
def sequence() -> tuple[np.ndarray, np.ndarray]:
    """A short run: commands that jump (0, 6 V, hold, −4 V, ...) and speeds with some noise."""
    rng = np.random.default_rng(3)
    u = np.repeat([0.0, 6.0, 6.0, -4.0, 2.5, 2.5, 0.0, 9.0], 5)
    model = load_models(TIMING_MODEL).motor("a")
    y = np.zeros(u.size)
    for k in range(u.size):  # the model's difference equation, nk = 1, three numerator terms
        a1, a2, b0, b1, b2 = model.theta
        past = [u[k - j] if k - j >= 0 else 0.0 for j in (1, 2, 3)]
        yk1 = y[k - 1] if k >= 1 else 0.0
        yk2 = y[k - 2] if k >= 2 else 0.0
        y[k] = -a1 * yk1 - a2 * yk2 + b0 * past[0] + b1 * past[1] + b2 * past[2]
    return u, y + rng.normal(0.0, 0.2, u.size)


@pytest.mark.parametrize("sigma", [0.5, 1.5])
def test_runtime_filter_with_timing_noise_matches_a_hand_written_one(sequence, sigma) -> None:
    u, y = sequence
    design = design_kalman(load_models(TIMING_MODEL).motor("a"), process_noise_std_v=0.05,
                           bias_drift_std_v=0.06, timing_noise_std_ticks=sigma)  # fmt: skip
    estimator = make_estimator(design)
    assert isinstance(estimator, KalmanSpeedEstimator)  # not the fixed-gain shortcut
    got = run_estimator(estimator, u, y)
    np.testing.assert_allclose(got, hand_filter(design, sigma, u, y), rtol=1e-9, atol=1e-9)
    # and the timing noise does something: the fixed gain gives other estimates after the jumps
    fixed = run_estimator(SteadyStateSpeedEstimator(design), u, y)
    assert np.max(np.abs(got - fixed)) > 0.05
    estimator.reset()  # a reset forgets the last command: the same run again gives the same
    np.testing.assert_allclose(run_estimator(estimator, u, y), got, rtol=0, atol=1e-12)


def test_without_timing_noise_the_fixed_gain_runs_as_before(sequence) -> None:
    u, y = sequence
    design = design_kalman(load_models(TIMING_MODEL).motor("a"))
    assert design.timing_noise_std_ticks == 0.0
    estimator = make_estimator(design)
    assert isinstance(estimator, SteadyStateSpeedEstimator)
    np.testing.assert_allclose(run_estimator(estimator, u, y), hand_filter(design, 0.0, u, y),
                               rtol=1e-9, atol=1e-9)  # fmt: skip


def test_old_controller_files_load_unchanged(workdir: Path) -> None:
    """A file without ``timing_noise_std_ticks`` (every file before it) loads with 0 and runs
    the fixed gain; the shipped serial file is such a file."""
    serial = load_controller("controllers/serial-poles.toml")
    assert "timing_noise_std_ticks" not in serial.motors["a"]["estimator"]
    assert "timing_noise_std_ticks" not in serial.request
    for ctrl in build_controllers(serial).values():
        assert isinstance(ctrl.estimator, SteadyStateSpeedEstimator)
        assert ctrl.estimator.design.timing_noise_std_ticks == 0.0
    text = Path("controllers/poles.toml").read_text(encoding="utf-8")
    old = re.sub(r"^timing_noise_std_ticks = .*\n", "", text, flags=re.M)
    assert old != text
    Path("controllers/old.toml").write_text(old, encoding="utf-8")
    for ctrl in build_controllers(load_controller("controllers/old.toml")).values():
        assert isinstance(ctrl.estimator, SteadyStateSpeedEstimator)


def test_design_writes_the_loop_delay_and_the_timing_noise(capsys, workdir: Path) -> None:
    argv = ["design", "models/ground-timing.toml", "--method", "poles", "--settling-time", "0.06",
            "--overshoot", "2", "--timing-noise-ticks", "0.5"]  # fmt: skip
    assert main([*argv, "--out", "controllers/zero.toml"]) == 0
    # the model file's loop_delay_ticks (1), not nk − 1 = 0: nk = 1 lands within the tick
    assert load_controller("controllers/zero.toml").loop_delay_ticks == 1
    assert main([*argv, "--loop-delay", "1", "--out", "controllers/one.toml"]) == 0
    capsys.readouterr()
    raw = tomllib.loads(Path("controllers/one.toml").read_text(encoding="utf-8"))
    assert raw["loop_delay_ticks"] == 1 and raw["plant_kind"] == "onboard"
    assert raw["request"]["loop_delay_ticks"] == 1
    assert raw["request"]["timing_noise_std_ticks"] == 0.5
    assert raw["motors"]["a"]["estimator"]["timing_noise_std_ticks"] == 0.5
    argv = DesignRequest(method="poles", timing_noise_std_ticks=0.5, loop_delay_ticks=1).to_argv(
        "m"
    )
    assert argv[-4:] == ["--timing-noise-ticks", "0.5", "--loop-delay", "1"]
    # without the options, the file has neither key (as before they existed)
    assert (
        main(["design", "models/ground.toml", "--method", "poles", "--out", "controllers/p.toml"])
        == 0
    )
    raw = tomllib.loads(Path("controllers/p.toml").read_text(encoding="utf-8"))
    assert "timing_noise_std_ticks" not in raw["request"]
    assert "loop_delay_ticks" not in raw["request"]
    assert "timing_noise_std_ticks" not in raw["motors"]["a"]["estimator"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["models/ground-timing.toml", "--loop-delay", "3"],
         "--loop-delay 3 does not fit a model with input delay nk = 1"),
        (["models/ground.toml", "--loop-delay", "0"],
         "--loop-delay 0 does not fit a model with input delay nk = 2"),
        (["models/ground.toml", "--loop-delay", "-1"], "--loop-delay must be >= 0 ticks"),
        (["models/ground.toml", "--timing-noise-ticks", "-0.5"],
         "--timing-noise-ticks must be in [0, 10] ticks"),
        (["models/ground.toml", "--timing-noise-ticks", "nan"],
         "--timing-noise-ticks must be a number, got nan"),
    ],
)  # fmt: skip
def test_refusals_are_one_line_exit_2(capsys, workdir: Path, argv, message) -> None:
    code = main(["design", argv[0], "--method", "poles", *argv[1:], "--out", "c.toml"])
    _, err = capsys.readouterr()
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert not Path("c.toml").exists()


def test_a_pi_without_estimator_refuses_timing_noise(capsys, workdir: Path) -> None:
    code = main(["design", "models/ground.toml", "--method", "pi", "--timing-noise-ticks", "0.5"])
    _, err = capsys.readouterr()
    assert code == 2 and "--timing-noise-ticks is for an estimator" in err


def test_a_file_with_a_bad_timing_noise_is_refused(workdir: Path) -> None:
    text = Path("controllers/poles.toml").read_text(encoding="utf-8")
    Path("controllers/bad.toml").write_text(
        text.replace("timing_noise_std_ticks = 0.5", "timing_noise_std_ticks = -1.0"), "utf-8"
    )
    with pytest.raises(Exception, match="timing_noise_std_ticks must be a number of ticks"):
        build_controllers(load_controller("controllers/bad.toml"))


def test_arduino_export_says_the_c_runs_the_fixed_gain(capsys, workdir: Path) -> None:
    code = main(["export", "controllers/poles.toml", "--arduino", "--out", "poles.h"])
    _, err = capsys.readouterr()
    assert code == 0
    assert err.count("\n") == 1 and err.startswith(
        "cartctl export: warning: the estimator's timing noise (0.5"
    )
    assert "fixed steady-state gain L" in err
    assert "// Note: the estimator's timing noise (0.5 ticks) is not in the C" in Path(
        "poles.h"
    ).read_text(encoding="utf-8")
    assert main(["export", "controllers/pi.toml", "--arduino", "--out", "pi.h"]) == 0
    assert capsys.readouterr().err == ""


def test_mat_export_carries_the_timing_noise(capsys, workdir: Path) -> None:
    assert main(["export", "--mat", "poles.mat", "controllers/poles.toml"]) == 0
    capsys.readouterr()
    mat = scipy.io.loadmat("poles.mat", simplify_cells=True)
    assert float(mat["motor_a"]["estimator"]["timing_noise_std_ticks"]) == 0.5
    assert mat["loop_delay_ticks"] == 1


def test_the_batch_loop_refuses_timing_noise() -> None:
    from cartctl.tune.batch import _filter_terms

    design = design_kalman(load_models(TIMING_MODEL).motor("a"), timing_noise_std_ticks=0.5)
    with pytest.raises(InputError, match="timing noise"):
        _filter_terms(KalmanSpeedEstimator(design))
