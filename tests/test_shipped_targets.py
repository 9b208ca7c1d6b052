"""The shipped controllers against the targets of the issue, through ``cartctl run --fast``.

- A 10 rad/s step with the ±12 V limit, judged on the true speed in the band max(2 %, one encoder
  count per tick = 0.3506 rad/s): on board (loop delay 1, ``--plant sim`` on the report's model
  and ``--plant physics`` with each command landing 3 ms after its tick, the presets' calibrated
  timing, and 10 ms, microOS's documented order: ``physics:actuation_ms=10``) at most 5 %
  overshoot and 90 ms (poles.toml) or 120 ms (pi.toml) settling; through the bridge
  (``--plant virtual``, the physics simulator behind the serial link in real time: loop delay 1
  too) the step reached and held, since how fast depends on the host's load (the figures:
  ``benchmarks/measure_shipped.py``); the fallback files for a serial loop of 3 ticks (``--plant sim`` on the report's model
  with nk = 4) at most 5 % and three times the time-optimal settling for that delay.
- The Kalman estimate of poles.toml on the physics simulator (square 8 rad/s, 2 s period): its
  RMS error against the true speed at most half the encoder's, over the whole run and over the
  steady windows alone (the last 0.5 s of each 1 s level), with no offset that follows the sign
  of the friction; and over the 10 rad/s step run; at 3 ms and at 10 ms. poles.toml meets the
  10 ms whole runs since it is designed on ``models/ground-timing.toml`` (nk = 1, fitted on the
  physics cart at 3 and 10 ms pooled) with timing noise: after each command change its
  time-varying estimator trusts its prediction less, so the tick a late command has not yet
  landed costs little (before: 0.68–0.80 of the encoder's error at 10 ms).

The physics targets assume the simulator calibrated to answer like the report's model; the
actuation timing of a real cart is unknown, hence both ends. The ratios are computed here from
the trace's columns (``true_speed_X``, ``estimate_X``, ``speed_X``).
"""

from __future__ import annotations

import itertools
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.data.read import read_trace
from cartctl.design.analysis import settling_bound
from cartctl.design.controllerfile import load_controller
from cartctl.measures.stepinfo import step_info
from realtime_upsets import link_upsets

ROOT = Path(__file__).resolve().parents[1]
QUANTUM_RAD_S = 2 * math.pi / 1792 / 0.01
"""One encoder count per tick (rad/s)."""
STEP_RAD_S = 10.0


def cartctl_run(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, np.ndarray]:
    """``cartctl run --fast --rerun off ARGV``; the trace's columns."""
    code = main(["run", "--fast", "--rerun", "off", "--json", *argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return read_trace(json.loads(out)["trace"]).columns()


@pytest.fixture(scope="module")
def fast_run():
    """:func:`cartctl_run`, each command once per module: the on-board step of poles.toml on the
    physics cart and its square runs serve the step, the estimate's steady state and the
    estimate's whole-run tests alike (each test in a copy of the same shipped files)."""
    done: dict[tuple[str, ...], dict[str, np.ndarray]] = {}

    def run(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, np.ndarray]:
        if argv not in done:
            done[argv] = cartctl_run(capsys, *argv)
        return done[argv]

    return run


def step_of(columns: dict[str, np.ndarray], motor: str) -> tuple[float, float | None]:
    """(overshoot %, settling s) of the true speed, in the band max(2 %, one count per tick)."""
    band = max(0.02, QUANTUM_RAD_S / STEP_RAD_S)
    info = step_info(columns["time_s"], columns[f"true_speed_{motor}"], reference=STEP_RAD_S,
                     onset_s=0.5, settling_band=band)  # fmt: skip
    return info.overshoot_percent, info.settling_time_s


def serial_model(workdir: Path) -> Path:
    """The report's ground model with the serial loop's delay: nk = 2 + 3."""
    text = (workdir / "models" / "ground.toml").read_text(encoding="utf-8")
    path = workdir / "models" / "ground-serial.toml"
    path.write_text(text.replace("nk = 2", "nk = 4"), encoding="utf-8")
    return path


ON_BOARD_PLANTS = ["sim", "physics", "physics:actuation_ms=3", "physics:actuation_ms=10"]
"""The on-board plants: the model, and the physics cart at the two ends of the actuation timing
(``physics`` itself is 3 ms)."""


@pytest.mark.parametrize(("name", "limit_s"), [("poles", 0.09), ("pi", 0.12)])
@pytest.mark.parametrize("plant", ON_BOARD_PLANTS)
def test_on_board_step(
    capsys, workdir: Path, fast_run, name: str, limit_s: float, plant: str
) -> None:
    assert load_controller(f"controllers/{name}.toml").loop_delay_ticks == 1
    columns = fast_run(capsys, "--plant", plant, "--controller", f"controllers/{name}.toml",
                          "--reference", f"step:{STEP_RAD_S:g}", "--duration", "2")  # fmt: skip
    for motor in ("a", "b"):
        overshoot, settling = step_of(columns, motor)
        assert overshoot <= 5.0, motor
        assert settling is not None and settling <= limit_s, motor
        assert np.abs(columns[f"voltage_{motor}"]).max() <= 12.0


@pytest.mark.parametrize("name", ["serial-poles", "serial-pi"])
def test_serial_step(capsys, workdir: Path, name: str) -> None:
    assert load_controller(f"controllers/{name}.toml").loop_delay_ticks == 3
    model = serial_model(workdir)
    columns = cartctl_run(capsys, "--plant", "sim", "--model", str(model), "--controller",
                          f"controllers/{name}.toml", "--reference", f"step:{STEP_RAD_S:g}",
                          "--duration", "2")  # fmt: skip
    models = load_models(model)
    for motor in ("a", "b"):
        bound_s = settling_bound(models.motor(motor), STEP_RAD_S).settling_time_s
        overshoot, settling = step_of(columns, motor)
        assert overshoot <= 5.0, motor
        assert settling is not None and settling <= 3.0 * bound_s, motor


@pytest.mark.realtime
@pytest.mark.filterwarnings("ignore::cartctl.errors.DataWarning")  # a busy machine may skip a tick
@pytest.mark.parametrize(
    ("controller", "plant"),
    [(None, "virtual"), ("controllers/poles.toml", "virtual:actuation_ms=10")],
)
def test_step_on_the_virtual_cart(
    capsys, workdir: Path, controller: str | None, plant: str
) -> None:
    """Through the serial path in real time (the virtual cart: the physics simulator behind the
    bridge, loop delay 1 measured from the echo, as on board), once per file and once per
    actuation timing (each file at each timing: ``test_on_board_step``, on the simulated clock):
    ``run --plant virtual`` takes pi.toml by itself; both on-board files run with the loop delay
    measured from the echo and bring the true speed to the step and hold it there."""
    given = [] if controller is None else ["--controller", controller]
    code = main(["run", "--plant", plant, "--rerun", "off", "--json", *given,
                 "--reference", f"step:{STEP_RAD_S:g}", "--duration", "2"])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads(out)
    assert summary["controller"] == (controller or "controllers/pi.toml")
    assert summary["loop_delay_ticks"] == 1
    link = summary["link"]
    assert link["host_frames_sent"] >= 200
    columns = read_trace(summary["trace"]).columns()
    # how fast it settles depends on when the host's replies land within each tick, which the
    # machine's load moves: the on-board targets are test_on_board_step's (simulated clock), the
    # figures on the virtual cart benchmarks/measure_shipped.py's; here the step is reached and held
    band = max(0.02 * STEP_RAD_S, QUANTUM_RAD_S)  # the settling band, as step_of's
    # a busy machine can hold the host up past the cart's watchdog or a tick: the link says so,
    # and then the speed has to come back to the step in the last 0.5 s rather than stay in the
    # band throughout (a watchdog trip late in the run leaves it no time to stay there: with the
    # full suite and a spinning process on 2 cores, 3 trips and 45 skipped ticks gave a median
    # error of 0.47 rad/s over the last 0.5 s, its smallest 0)
    upset = link_upsets(link)
    for motor in ("a", "b"):
        _, settling = step_of(columns, motor)
        error = np.abs(columns[f"true_speed_{motor}"][-50:-1] - STEP_RAD_S)  # last 0.5 s
        seen = {k: link[k] for k in ("watchdog_trips", "missed_ticks", "skipped_ticks",
                                     "lost_frames", "host_frames_lost", "loop_delay_ticks_seen")}  # fmt: skip
        assert upset or settling is not None, (motor, np.round(error, 2), seen)
        assert (error.min() if upset else error.max()) <= band, (
            motor,
            np.round(error, 2),
            seen,
        )


def steady_windows(reference: np.ndarray) -> list[slice]:
    """The second half of every stretch of constant reference."""
    edges = np.r_[0, np.flatnonzero(np.diff(reference) != 0.0) + 1, reference.size]
    return [slice(a + (b - a) // 2, b) for a, b in itertools.pairwise(edges)]


def estimator_errors(motor_runs: dict[str, np.ndarray], motor: str):
    """(estimate − true, measured − true, steady windows) of one motor."""
    true = motor_runs[f"true_speed_{motor}"]
    est = motor_runs[f"estimate_{motor}"] - true
    meas = motor_runs[f"speed_{motor}"] - true
    return est, meas, steady_windows(motor_runs[f"reference_{motor}"])


def rms(error: np.ndarray, index: np.ndarray | slice = slice(None)) -> float:
    return float(np.sqrt(np.mean(error[index] ** 2)))


@pytest.fixture(params=["physics", "physics:actuation_ms=10"])
def poles_square(request, capsys, workdir: Path, fast_run) -> dict[str, np.ndarray]:
    """poles.toml on the physics cart (3 ms and 10 ms actuation), square 8 rad/s with a 2 s
    period, 10 s."""
    return fast_run(capsys, "--plant", request.param, "--controller", "controllers/poles.toml",
                    "--reference", "square:8:2", "--duration", "10")  # fmt: skip


def test_pole_placement_estimate_beats_the_encoder_in_steady_state(poles_square) -> None:
    for motor in ("a", "b"):
        est, meas, windows = estimator_errors(poles_square, motor)
        steady = np.concatenate([np.arange(w.start, w.stop) for w in windows])
        assert len(windows) == 10
        assert rms(est, steady) <= 0.5 * rms(meas, steady), motor
        # no offset following the sign of the friction: each steady window is centred
        assert max(abs(float(np.mean(est[w]))) for w in windows) < 0.1, motor
        # and over the whole run, transients included, it is still better than the encoder
        assert rms(est) < rms(meas), motor


@pytest.mark.parametrize("plant", ["physics", "physics:actuation_ms=10"])
@pytest.mark.parametrize("reference", ["square:8:2", "step:10"])
def test_pole_placement_estimate_halves_the_encoder_error_over_the_whole_run(
    capsys, workdir: Path, fast_run, plant: str, reference: str
) -> None:
    columns = fast_run(capsys, "--plant", plant, "--controller", "controllers/poles.toml",
                       "--reference", reference, "--duration", "10" if "square" in reference
                       else "2")  # fmt: skip
    for motor in ("a", "b"):
        est, meas, _ = estimator_errors(columns, motor)
        assert rms(est) <= 0.5 * rms(meas), motor


def test_the_pi_runs_on_the_encoder(capsys, workdir: Path) -> None:
    """pi.toml has no estimator: the estimate it logs is the measured speed (ratio 1)."""
    assert load_controller("controllers/pi.toml").request["estimator"] == "none"
    columns = cartctl_run(capsys, "--plant", "physics:actuation_ms=10", "--controller",
                          "controllers/pi.toml", "--reference", "step:10", "--duration", "1")  # fmt: skip
    for motor in ("a", "b"):
        np.testing.assert_array_equal(columns[f"estimate_{motor}"], columns[f"speed_{motor}"])


@pytest.mark.parametrize(("name", "delay", "first_tick"), [("poles", 1, 1), ("serial-poles", 3, 4)])
def test_estimator_has_the_loop_delay_and_a_disturbance_state(
    name: str, delay: int, first_tick: int
) -> None:
    """A voltage first shows in the estimator's speed loop delay + 1 ticks later on the report's
    model (serial-poles.toml: the measured speed is the average over the tick after it lands),
    and already loop delay ticks later on the timing model of poles.toml (it lands within the
    tick, and the average over that tick sees part of it); b enters where the voltage does."""
    raw = tomllib.loads((ROOT / "controllers" / f"{name}.toml").read_text(encoding="utf-8"))
    assert raw["loop_delay_ticks"] == delay
    for entry in raw["motors"].values():
        est = entry["estimator"]
        A, B, C = (np.asarray(est[k], dtype=float) for k in ("A", "B", "C"))
        n = A.shape[0] - 1  # the last state is the disturbance
        markov = [float(C @ np.linalg.matrix_power(A, j - 1) @ B) for j in range(1, n + 1)]
        first = next(j for j, h in enumerate(markov, start=1) if abs(h) > 1e-9)
        assert first == first_tick
        assert est["bias_drift_std_v"] > 0.0
        np.testing.assert_allclose(A[:n, n], B[:n])  # b adds to u
        assert A[n, n] == 1.0 and not A[n, :n].any()
        assert entry["Ki"] == 0.0 and entry["K"][-1] == 1.0  # u carries −b̂: the integral action
        assert len(entry["K"]) == n + 1


def test_poles_runs_the_timing_model_with_timing_noise() -> None:
    """poles.toml: designed on the timing model for a loop delay of 1, with timing noise in its
    estimator, which ``run`` then runs with its covariance propagated (not the fixed gain)."""
    from cartctl.design.controllerfile import build_controllers
    from cartctl.runtime.kalman import KalmanSpeedEstimator

    controller = load_controller("controllers/poles.toml")
    assert Path(controller.model_path).name == "ground-timing.toml"
    assert controller.loop_delay_ticks == 1 and controller.request["loop_delay_ticks"] == 1
    assert load_models(controller.model_path).motor("a").nk == 1
    for motor, ctrl in build_controllers(controller).items():
        assert controller.motors[motor]["estimator"]["timing_noise_std_ticks"] == 0.5
        assert isinstance(ctrl.estimator, KalmanSpeedEstimator)
