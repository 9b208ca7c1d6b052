"""Identification: exact recovery, agreement with plain least squares, delay estimation, the
prefilter's effect, output-error refinement, and refused data. Mostly through ``cartctl identify``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.trace import Trace, write_trace
from cartctl.errors import InputError
from cartctl.identification.arx import IdentificationError, fit_arx
from cartctl.identification.orders import delay_evidence
from cartctl.identification.pipeline import Prefilter
from cartctl.model import ArxModel
from cartctl.plants.physics import PhysicsPlant
from cartctl.runtime.loop import run_experiment
from cartctl.signals import prbs, square

THETA_A = [-0.9356, 0.2173, 0.6466, -0.07751]
THETA_B = [-0.9082, 0.1968, 0.6886, -0.1068]


def _trace(
    path: Path, ua: np.ndarray, ya: np.ndarray, ub: np.ndarray | None = None, yb=None
) -> Path:
    n = ua.size
    zeros = np.zeros(n)
    write_trace(
        Trace(
            np.arange(n) * 0.01, ua, zeros if ub is None else ub, ya, zeros if yb is None else yb
        ),
        path,
    )
    return path


def _noisy_square(
    tmp_path: Path, *, cycles: int, noise_std: float, seed: int
) -> tuple[Path, np.ndarray]:
    """sq.csv: a 10 V square of ``cycles`` cycles on motor a through THETA_A, with seeded white
    noise of ``noise_std`` rad/s on the speed; its path and the voltage."""
    u = square(10.0, cycles=cycles)
    rng = np.random.default_rng(seed)
    y = ArxModel.from_theta(THETA_A).simulate(u) + rng.normal(0.0, noise_std, u.size)
    return _trace(tmp_path / "sq.csv", u, y), u


def _identify_json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    code = main(["identify", *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


@pytest.mark.parametrize("nk", [1, 2, 3, 4])
def test_noise_free_data_gives_the_true_model_and_delay(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, nk: int
) -> None:
    ma = ArxModel.from_theta(THETA_A, nk=nk)
    mb = ArxModel.from_theta(THETA_B, nk=nk)
    ua, ub = prbs(8.0, duration_s=10.0, seed=3), square(10.0, cycles=4)[:1000]
    path = _trace(tmp_path / "exact.csv", ua, ma.simulate(ua), ub, mb.simulate(ub))
    doc = _identify_json(capsys, str(path), "--delay", str(nk))
    assert doc["Ts"] == 0.01
    np.testing.assert_allclose(doc["motors"]["a"]["theta"], THETA_A, atol=1e-8)
    np.testing.assert_allclose(doc["motors"]["b"]["theta"], THETA_B, atol=1e-8)
    assert doc["motors"]["a"]["nk"] == nk
    assert doc["motors"]["a"]["fit_simulation_percent"] == pytest.approx(100.0, abs=1e-6)
    auto = _identify_json(capsys, str(path), "--delay", "auto")
    for motor, theta in (("a", THETA_A), ("b", THETA_B)):
        entry = auto["motors"][motor]
        assert entry["nk"] == nk
        assert entry["delay_estimate"]["nk"] == nk
        assert len(entry["delay_estimate"]["candidates"]) == 6
        np.testing.assert_allclose(entry["theta"], theta, atol=1e-8)


def test_json_follows_its_contract(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    model = ArxModel.from_theta(THETA_A)
    u = square(10.0, cycles=2)
    doc = _identify_json(
        capsys, str(_trace(tmp_path / "a.csv", u, model.simulate(u))), "--motor", "a"
    )
    a = doc["motors"]["a"]
    required = {
        "theta",
        "nk",
        "num",
        "den",
        "theta_std",
        "fit_simulation_percent",
        "fit_prediction_percent",
    }
    assert required <= set(a)
    np.testing.assert_allclose(a["den"], [1.0, THETA_A[0], THETA_A[1], 0.0], atol=1e-8)
    np.testing.assert_allclose(a["num"], THETA_A[2:], atol=1e-8)
    assert list(doc["motors"]) == ["a"]


def test_noisy_theta_equals_numpy_lstsq(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    model = ArxModel.from_theta(THETA_A)
    u = square(10.0, cycles=4)
    y = model.simulate(u) + rng.normal(0.0, 0.4, u.size)
    doc = _identify_json(capsys, str(_trace(tmp_path / "noisy.csv", u, y)), "--motor", "a")
    k = np.arange(3, u.size)
    phi = np.column_stack([-y[k - 1], -y[k - 2], u[k - 2], u[k - 3]])
    reference = np.linalg.lstsq(phi, y[k], rcond=None)[0]
    np.testing.assert_allclose(doc["motors"]["a"]["theta"], reference, atol=1e-8)
    # the standard deviations are those of the textbook formula σ² (ΦᵀΦ)⁻¹
    resid = y[k] - phi @ reference
    cov = resid @ resid / (k.size - 4) * np.linalg.inv(phi.T @ phi)
    np.testing.assert_allclose(doc["motors"]["a"]["theta_std"], np.sqrt(np.diag(cov)), rtol=1e-6)


def test_oe_beats_arx_in_simulation_on_noisy_physics_data(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    u = square(10.0, cycles=5)
    trace = run_experiment(PhysicsPlant("ground", noise_std_rad_s=0.3, seed=5), u, u).trace
    path = tmp_path / "ground.csv"
    write_trace(trace, path)
    doc = _identify_json(capsys, str(path), "--method", "oe")
    for motor in ("a", "b"):
        entry = doc["motors"][motor]
        assert entry["method"] == "oe"
        assert entry["oe"]["theta"] == entry["theta"]
        assert entry["oe"]["fit_simulation_percent"] >= entry["arx"]["fit_simulation_percent"]
        assert entry["arx"]["fit_simulation_percent"] > 90.0


def test_prefilter_comparison_in_one_command(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    u = square(10.0, cycles=5)
    trace = run_experiment(PhysicsPlant("air", noise_std_rad_s=0.3, seed=2), u, u).trace
    path = tmp_path / "air.csv"
    write_trace(trace, path)
    code = main(["identify", str(path), "--prefilter", "butter"])
    out, _ = capsys.readouterr()
    assert code == 0
    assert "ARX, unfiltered" in out
    assert "ARX, prefiltered" in out
    doc = _identify_json(
        capsys, str(path), "--prefilter", "butter", "--cutoff-hz", "20", "--order", "6"
    )
    filtered, raw = doc["motors"]["a"], doc["motors"]["a"]["unfiltered"]
    # both fits are reported, the filter visibly moves the poles, and both simulate the raw data well
    poles_f = np.sort_complex(np.roots(filtered["den"]))
    poles_r = np.sort_complex(np.roots(raw["den"]))
    assert np.max(np.abs(poles_f - poles_r)) > 0.05
    assert filtered["fit_simulation_percent"] > 90.0
    assert raw["fit_simulation_percent"] > 90.0


def test_model_file_written_with_provenance(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from cartctl.data.modelfile import load_models

    model = ArxModel.from_theta(THETA_B, nk=3)
    u = prbs(6.0, duration_s=8.0)
    data = _trace(tmp_path / "b.csv", u, model.simulate(u))
    out = tmp_path / "models" / "mine.toml"
    assert main(["identify", str(data), "--motor", "a", "--delay", "auto", "--out", str(out)]) == 0
    capsys.readouterr()
    models = load_models(out)
    np.testing.assert_allclose(models.motor("a").theta, THETA_B, atol=1e-8)
    assert models.motor("a").nk == 3
    assert models.provenance.data == (str(data),)
    assert models.provenance.method == "arx"
    assert "delay nk = 3 estimated" in models.provenance.notes
    assert "theta_std" in models.stats["a"]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda n: (np.full(n, 5.0), np.linspace(0, 10, n)), "constant"),
        (lambda n: (np.tile([10.0, -10.0], 10), np.arange(20.0)), "too few samples"),
    ],
)
def test_data_that_cannot_give_a_model(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, make, message: str
) -> None:
    u, y = make(300)
    path = _trace(tmp_path / "bad.csv", u, y)
    code = main(["identify", str(path), "--motor", "a"])
    _, err = capsys.readouterr()
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_nan_file_gives_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "nan.csv"
    path.write_text("time_s,voltage_a,voltage_b,speed_a,speed_b\n0,1,0,0,0\n0.01,1,0,nan,0\n")
    code = main(["identify", str(path)])
    _, err = capsys.readouterr()
    assert code == 2
    assert "nan.csv" in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--delay", "soon"], "--delay must be 'auto' or a whole number"),
        (["--prefilter", "butter", "--cutoff-hz", "60"], "Nyquist"),
        (["--prefilter", "butter", "--order", "0"], "order"),
        (["--na", "-1"], "na (--na) must be"),
        (["--compare", "missing.toml"], "model file not found"),
    ],
)
def test_bad_options(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, argv: list[str], message: str
) -> None:
    u = square(10.0, cycles=2)
    path = _trace(tmp_path / "ok.csv", u, ArxModel.from_theta(THETA_A).simulate(u))
    code = main(["identify", str(path), *argv])
    _, err = capsys.readouterr()
    assert code == 2
    assert message in err


def test_rank_deficient_regression_is_refused() -> None:
    # A single sinusoid excites only two parameters' worth of dynamics for a four-parameter model.
    t = np.arange(2000) * 0.01
    u = np.sin(2 * np.pi * 1.0 * t)
    y = np.zeros_like(u)  # the output is identically zero: its lags are zero columns
    with pytest.raises(IdentificationError, match="rank deficient"):
        fit_arx([(y, u)])


def test_unused_motor_is_skipped_or_refused(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    u = square(10.0, cycles=2)
    path = _trace(tmp_path / "onlya.csv", u, ArxModel.from_theta(THETA_A).simulate(u))
    doc = _identify_json(capsys, str(path))
    assert list(doc["motors"]) == ["a"]
    code = main(["identify", str(path), "--motor", "b"])
    _, err = capsys.readouterr()
    assert code == 2
    assert "motor b has no excitation: its voltage is zero" in err


def test_averaging_cycles_reduces_noise_bias() -> None:
    rng = np.random.default_rng(8)
    model = ArxModel.from_theta(THETA_A)
    u = square(10.0, cycles=12)
    y = model.simulate(u) + rng.normal(0.0, 0.1, u.size)
    from cartctl.identification.pipeline import IdentifyRequest, identify

    trace = Trace(np.arange(u.size) * 0.01, u, np.zeros_like(u), y, np.zeros_like(u), source="x")
    plain = identify([trace], IdentifyRequest(motors=("a",))).motors["a"]
    averaged = identify([trace], IdentifyRequest(motors=("a",), average=True)).motors["a"]
    assert averaged.cycles_averaged == 11
    err_plain = np.linalg.norm(plain.chosen.model.theta - model.theta)
    err_avg = np.linalg.norm(averaged.chosen.model.theta - model.theta)
    assert err_avg < err_plain / 3


def test_prefilter_and_average_together_fit_the_periodic_steady_state(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # the prefilter's start from rest made the input aperiodic, so --average always refused
    u = square(10.0, cycles=6)
    path = _trace(tmp_path / "sq.csv", u, ArxModel.from_theta(THETA_A).simulate(u))
    for zero_phase in ([], ["--zero-phase"]):
        doc = _identify_json(capsys, str(path), "--average", "--prefilter", "butter", *zero_phase)
        motor = doc["motors"]["a"]
        assert motor["cycles_averaged"] == 5
        # an LTI filter on both signals keeps the ARX relation exact on noise-free data
        np.testing.assert_allclose(motor["theta"], THETA_A, atol=1e-6)


def test_the_order_table_of_an_averaged_fit_is_on_the_averaged_cycle(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # it was fitted on the raw record, so its row of the chosen orders disagreed with the model
    path, u = _noisy_square(tmp_path, cycles=6, noise_std=0.2, seed=5)
    doc = _identify_json(capsys, str(path), "--average", "--orders", "na=1:2,nb=1:3,nk=1:2")
    motor = doc["motors"]["a"]
    period = u.size // 6
    assert motor["n_samples"] == period
    rows = {(r["na"], r["nb"], r["nk"]): r for r in motor["orders"]}
    assert {r["n_equations"] for r in rows.values()} == {period}  # one equation per tick of it
    own = rows[(motor["na"], motor["nb"], motor["nk"])]
    assert own["fit_percent"] == pytest.approx(motor["fit_simulation_percent"], abs=1e-9)


def test_periodic_prefilter_is_the_filters_steady_state() -> None:
    from scipy import signal

    rng = np.random.default_rng(3)
    cycle = rng.normal(size=120)
    sos = signal.butter(6, 20.0, fs=100.0, output="sos")
    repeated = np.tile(cycle, 40)  # the transient decays long before the last cycles
    causal = Prefilter().apply_periodic(cycle, 0.01)
    np.testing.assert_allclose(causal, signal.sosfilt(sos, repeated)[-120:], atol=1e-9)
    zero_phase = Prefilter(zero_phase=True).apply_periodic(cycle, 0.01)
    np.testing.assert_allclose(zero_phase, signal.sosfiltfilt(sos, repeated)[2400:2520], atol=1e-9)


def test_prefilter_checks() -> None:
    with pytest.raises(InputError):
        Prefilter(cutoff_hz=-1.0)
    assert Prefilter().describe() == "butter order 6, 20 Hz, causal"
    x = np.ones(500)
    assert Prefilter().apply(x, 0.01)[-1] == pytest.approx(1.0)  # unit DC gain
    assert Prefilter(zero_phase=True).apply(x, 0.01)[250] == pytest.approx(1.0, abs=1e-6)


def test_delay_estimate_ties_go_to_the_smaller_delay() -> None:
    # b = [0, 1] at nk = 2 is a pure delay of 3: nk = 2 and nk = 3 both represent it exactly
    model = ArxModel.from_theta([-0.5, 0.0, 1.0], na=1, nb=2, nk=2)
    u = prbs(5.0, duration_s=5.0)
    est = delay_evidence([(model.simulate(u), u)], na=1, nb=2, candidates=(1, 2, 3, 4))
    assert est.residual_rms[1] < 1e-9
    assert est.residual_rms[2] < 1e-9
    assert est.nk == 2


def test_report_writes_the_figures_and_summary(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, air_path: Path
) -> None:
    import matplotlib.image

    u = square(10.0, cycles=3)
    trace = run_experiment(PhysicsPlant("air", noise_std_rad_s=0.2, seed=4), u, u).trace
    data = tmp_path / "air.csv"
    write_trace(trace, data)
    report = tmp_path / "report"
    code = main(["identify", str(data), "--prefilter", "butter", "--method", "oe",
                 "--report", str(report), "--compare", str(air_path), "--json"])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)  # --json stays one object even with --report
    summary = (report / "summary.md").read_text()
    for name in ("io", "etfe_a", "etfe_b", "pzmap_a", "pzmap_b", "simulation_a", "simulation_b"):
        png = report / f"{name}.png"
        image = matplotlib.image.imread(png)
        assert image.shape[0] > 300
        assert image.shape[1] > 500
        assert f"({name}.png)" in summary
    # the table shows the same numbers as --json
    fit = doc["motors"]["a"]["oe"]["fit_simulation_percent"]
    assert "| OE | 2 |" in summary
    assert f"{fit:.2f}" in summary
    assert "ARX, unfiltered" in summary
    assert "ARX, prefiltered" in summary


def test_average_with_oe_says_the_refinement_is_on_the_raw_experiments(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # the OE refinement simulates from rest, so it runs on the raw record while the ARX start is
    # fitted on the averaged cycles; that went unsaid (the OE row did not move with --average)
    path, u = _noisy_square(tmp_path, cycles=4, noise_std=0.2, seed=6)
    doc = _identify_json(capsys, str(path), "--average", "--method", "oe")
    motor = doc["motors"]["a"]
    assert motor["cycles_averaged"] == 3
    assert motor["arx"]["n_samples"] == u.size // 4  # one cycle's equations
    assert motor["oe"]["n_samples"] == u.size  # the raw record
    assert any("raw experiments" in note for note in motor["oe"]["notes"])
    assert main(["identify", str(path), "--average", "--method", "oe"]) == 0
    assert "OE: --average" in capsys.readouterr().out


def test_compare_refuses_a_model_of_another_sample_period(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, air_path: Path
) -> None:
    # a 20 ms model was simulated on 10 ms data as if it were 10 ms: a fit in the table, poles
    # in Hz of its own period; validate refuses the same mismatch
    u = square(10.0, cycles=2)
    path = str(_trace(tmp_path / "sq.csv", u, ArxModel.from_theta(THETA_A).simulate(u)))
    slow = tmp_path / "slow.toml"
    slow.write_text(
        air_path.read_text(encoding="utf-8").replace("period_s = 0.01", "period_s = 0.02"),
        encoding="utf-8",
    )
    assert main(["identify", path, "--compare", str(air_path), str(slow)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--compare" in err[0] and "slow.toml" in err[0]
    assert "20 ms" in err[0] and "10 ms" in err[0]


def test_the_delay_evidence_of_an_averaged_fit_is_on_the_averaged_cycle(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # it was on the raw record (the same evidence with and without --average), while the model
    # and the order table are fitted on the averaged cycle
    path, u = _noisy_square(tmp_path, cycles=6, noise_std=0.5, seed=7)
    path = str(path)
    plain = _identify_json(capsys, path, "--delay", "auto")["motors"]["a"]["delay_estimate"]
    doc = _identify_json(capsys, path, "--delay", "auto", "--average")
    averaged = doc["motors"]["a"]["delay_estimate"]
    assert plain["equations"] > u.size // 2 and averaged["equations"] == u.size // 6
    assert averaged["nk"] == doc["motors"]["a"]["nk"] == 2
    ours = {c["nk"]: c["residual_rms"] for c in averaged["candidates"]}
    assert ours[2] < 0.5 * {c["nk"]: c["residual_rms"] for c in plain["candidates"]}[2]


def test_average_on_too_few_cycles_names_the_option_and_the_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # the line said only "needs at least 2 whole cycle(s) after dropping the first (transient)"
    u = square(10.0, cycles=2)
    path = str(_trace(tmp_path / "sq.csv", u, ArxModel.from_theta(THETA_A).simulate(u)))
    assert main(["identify", path, "--average"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"cartctl identify: error: --average on {path}: needs at least 2 whole")
