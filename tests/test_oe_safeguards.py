"""Output error that cannot diverge, and the warnings around it: OE never below its ARX start and
its poles within |z| ≤ 0.99; a cross-correlation bound that never collapses to 0; ``inspect``
flagging a slow or marginal pole; ``design`` warning on a lightly damped closed loop.

Expectations are computed here independently: fits by the NRMSE formula on scipy's ``lfilter``,
pole magnitudes by ``numpy.roots``, damping by python-control's ``damp``.
"""

from __future__ import annotations

import json
from pathlib import Path

import control
import numpy as np
import pytest
from scipy import signal

from cartctl.cli import main
from cartctl.identification.arx import fit_arx
from cartctl.identification.diagnostics import Z_99, residual_test
from cartctl.identification.oe import fit_oe
from cartctl.model import ArxModel

Z99 = 2.576


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _nrmse(y: np.ndarray, y_hat: np.ndarray) -> float:
    return 100.0 * (1.0 - np.linalg.norm(y - y_hat) / np.linalg.norm(y - y.mean()))


def _sim_fit(theta: np.ndarray, na: int, nk: int, y: np.ndarray, u: np.ndarray) -> float:
    a = np.concatenate([[1.0], theta[:na]])
    b = np.concatenate([np.zeros(nk), theta[na:]])
    return _nrmse(y, signal.lfilter(b, a, u))


def _radius(theta: np.ndarray, na: int) -> float:
    return float(np.max(np.abs(np.roots(np.concatenate([[1.0], theta[:na]])))))


def _steps(rng: np.random.Generator, n: int, level_v: float = 5.0) -> np.ndarray:
    """Random ±level steps held 2–20 ticks."""
    u = np.empty(n)
    k = 0
    while k < n:
        hold = int(rng.integers(2, 21))
        u[k : k + hold] = rng.choice([-level_v, level_v])
        k += hold
    return u


def _coloured_oe_data(seed: int, n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """An OE system (poles 0.9, 0.6, nk = 1) with strongly coloured measurement noise: ARX biased."""
    rng = np.random.default_rng(seed)
    u = _steps(rng, n)
    a = np.poly([0.9, 0.6])
    y0 = signal.lfilter([0.0, 0.5, 0.2], a, u)
    noise = signal.lfilter([1.0], [1.0, -0.97], rng.normal(0.0, 0.6, n))
    return y0 + noise, u


# -- (a) the prefilter + OE example of docs/identification.md, through the CLI --------------------


def test_readme_prefilter_oe_example_is_never_below_arx_and_keeps_poles_inside(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    data = tmp_path / "air.csv"
    code, _, err = _run(capsys, "excite", "--plant", "physics", "--preset", "air", "--signal",
                        "square", "--amplitude", "10", "--noise", "0.3", "--seed", "1",
                        "--out", str(data))  # fmt: skip
    assert code == 0, err
    code, out, err = _run(
        capsys, "identify", str(data), "--prefilter", "butter", "--method", "oe", "--json"
    )
    assert code == 0, err
    doc = json.loads(out)
    for motor in ("a", "b"):
        entry = doc["motors"][motor]
        assert entry["method"] == "oe"
        assert entry["oe"]["fit_simulation_percent"] >= entry["arx"]["fit_simulation_percent"]
        assert np.max(np.abs(np.roots(entry["den"]))) <= 0.995
        res = entry["residuals"]
        assert res["cross_bound_99"] >= Z99 / np.sqrt(res["n_samples"]) * (1 - 1e-12)


# -- (b) OE from a bad ARX start -------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_oe_is_never_below_a_biased_arx_start_and_bounded(seed: int) -> None:
    y, u = _coloured_oe_data(seed)
    arx = fit_arx([(y, u)], na=2, nb=2, nk=1)
    oe = fit_oe([(y, u)], arx.model)
    arx_fit = _sim_fit(np.asarray(arx.model.theta), 2, 1, y, u)
    oe_fit = _sim_fit(np.asarray(oe.model.theta), 2, 1, y, u)
    assert oe_fit >= arx_fit - 1e-9
    assert oe.fit_simulation_percent == pytest.approx(oe_fit)
    assert _radius(np.asarray(oe.model.theta), 2) <= 0.99 + 1e-9
    # the biased start is improved on, towards the true poles 0.9 and 0.6
    assert not oe.start_kept
    assert oe_fit > arx_fit
    poles = np.sort(np.abs(np.roots(np.concatenate([[1.0], oe.model.ar]))))
    np.testing.assert_allclose(poles, [0.6, 0.9], atol=0.08)


def test_oe_with_a_prefiltered_criterion_is_judged_on_the_unfiltered_data() -> None:
    y, u = _coloured_oe_data(4)
    b, a = signal.butter(6, 0.4)  # 20 Hz at Ts = 10 ms
    yf, uf = signal.lfilter(b, a, y), signal.lfilter(b, a, u)
    arx = fit_arx([(yf, uf)], na=2, nb=2, nk=1)
    oe = fit_oe([(yf, uf)], arx.model, eval_segments=[(y, u)])
    assert _sim_fit(np.asarray(oe.model.theta), 2, 1, y, u) >= _sim_fit(
        np.asarray(arx.model.theta), 2, 1, y, u
    )
    assert _radius(np.asarray(oe.model.theta), 2) <= 0.99 + 1e-9


def test_oe_projects_an_unstable_start_inside_the_bound() -> None:
    y, u = _coloured_oe_data(5)
    start = ArxModel.from_theta([*np.poly([1.05, 0.6])[1:], 0.5, 0.2], nk=1)
    oe = fit_oe([(y, u)], start)
    assert oe.start_projected
    assert _radius(np.asarray(oe.model.theta), 2) <= 0.99 + 1e-9
    assert np.isfinite(_sim_fit(np.asarray(oe.model.theta), 2, 1, y, u))
    assert any("projected inside" in note for note in oe.notes)


def test_oe_says_when_the_pole_bound_is_active() -> None:
    rng = np.random.default_rng(6)
    u = _steps(rng, 3000)
    y = signal.lfilter([0.0, 0.02, 0.01], np.poly([0.998, 0.5]), u)  # a pole beyond 0.99
    arx = fit_arx([(y, u)], na=2, nb=2, nk=1)
    assert _radius(np.asarray(arx.model.theta), 2) > 0.99  # the exact start is beyond the bound
    oe = fit_oe([(y, u)], arx.model)
    assert _radius(np.asarray(oe.model.theta), 2) <= 0.99 + 1e-9
    assert oe.pole_bound_active
    assert any("bound |z| ≤ 0.99 is active" in note for note in oe.notes)


# -- (c) the cross-correlation bound on a filtered, periodic input ---------------------------------


def test_cross_bound_never_collapses_on_a_filtered_periodic_input() -> None:
    n = 1500
    square = np.where((np.arange(n) // 100) % 2 == 0, 10.0, -10.0)
    b, a = signal.butter(6, 0.4)
    u = signal.lfilter(b, a, square)  # low-frequency, strongly correlated input
    rng = np.random.default_rng(7)
    # a residual oscillating near Nyquist: r_ε(τ) ≈ (−1)^τ, where r_u(τ) ≈ 1
    e = 0.5 * (-1.0) ** np.arange(n) * (1.0 + 0.05 * rng.normal(size=n))
    test = residual_test([(e, u)])
    assert test.cross_variance < 0.1  # Ljung's estimate of P is near zero or negative here
    assert test.cross_bound_99 >= Z_99 / np.sqrt(n) * (1 - 1e-12)
    assert test.cross_bound_99 == pytest.approx(Z99 / np.sqrt(n), rel=1e-3)
    assert "±0.000" not in test.summary()


# -- (d) inspect flags a pole at 0.995 ----------------------------------------------------------------


def test_inspect_flags_a_slow_or_marginal_pole(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    c, d = (float(v) for v in np.poly([0.995, 0.5])[1:])  # A = (1 − 0.995 q⁻¹)(1 − 0.5 q⁻¹)
    path = tmp_path / "slow.toml"
    path.write_text(
        'format = "cartctl-model/1"\nperiod_s = 0.01\n\n[provenance]\nsource = "test"\n'
        'created = "2026-11-25"\n\n'
        f"[motors.a]\ntheta = [{c!r}, {d!r}, 0.01, 0.0]\nna = 2\nnb = 2\nnk = 2\n\n"
        "[motors.b]\ntheta = [-0.9356, 0.2173, 0.6466, -0.07751]\nna = 2\nnb = 2\nnk = 2\n"
    )
    code, out, err = _run(capsys, "inspect", str(path), "--json")
    assert code == 0, err
    doc = json.loads(out)
    a, b = doc["motors"]["a"], doc["motors"]["b"]
    assert a["stable"] is True and a["slow_or_marginal"] is True
    assert "slow_or_marginal" in a["flags"]
    flagged = [p for p in a["poles"] if p["slow_or_marginal"]]
    assert len(flagged) == 1 and flagged[0]["re"] == pytest.approx(0.995)
    for p in a["poles"]:  # the JSON output's keys are all still there
        assert {"re", "im", "kind", "freq_hz", "damping"} <= set(p)
    assert b["slow_or_marginal"] is False and b["flags"] == []
    assert not any(p["slow_or_marginal"] for p in b["poles"])
    code, out, _ = _run(capsys, "inspect", str(path))
    assert code == 0
    block_a, block_b = out.split("motor b:")
    assert "SLOW OR MARGINAL" in block_a and "0.9950" in block_a
    assert "slow or marginal (|z| > 0.99)" in block_a
    assert "SLOW OR MARGINAL" not in block_b and "slow or marginal (|z|" not in block_b


def test_inspect_json_flags_slow_or_marginal_only_on_a_stable_model(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """docs/identification.md: "slow_or_marginal" is a stable but slow pole (as the table's row
    and summary line); a model with a pole outside the unit circle or on it is not flagged so."""
    theta = {
        m: [float(v) for v in np.poly(poles)[1:]]
        for m, poles in (("a", [1.05, 0.995]), ("b", [1.0, 0.5]))
    }
    path = tmp_path / "unstable.toml"
    path.write_text(
        'format = "cartctl-model/1"\nperiod_s = 0.01\n\n[provenance]\nsource = "test"\n'
        'created = "2026-11-25"\n\n'
        + "".join(
            f"[motors.{m}]\ntheta = [{c!r}, {d!r}, 0.01, 0.0]\nna = 2\nnb = 2\nnk = 2\n\n"
            for m, (c, d) in theta.items()
        )
    )
    code, out, err = _run(capsys, "inspect", str(path), "--json")
    assert code == 0, err
    a, b = (json.loads(out)["motors"][m] for m in "ab")
    assert a["stable"] is False and a["slow_or_marginal"] is False and a["flags"] == []
    flagged = {round(p["magnitude"], 3): p["slow_or_marginal"] for p in a["poles"]}
    assert flagged == {1.05: False, 0.995: True, 0.0: False}  # 0.995 as its row says
    assert b["stable"] is False and b["slow_or_marginal"] is False and b["flags"] == []
    assert not any(p["slow_or_marginal"] for p in b["poles"])  # on the unit circle
    code, out, _ = _run(capsys, "inspect", str(path))
    assert "unstable (|z| > 1)" in out and "on the unit circle" in out
    assert "SLOW OR MARGINAL" not in out and out.count("slow or marginal (|z| > 0.99)") == 1


# -- (e) design warns on a lightly damped loop ----------------------------------------------------


def test_design_warns_on_a_lightly_damped_closed_loop(
    capsys: pytest.CaptureFixture[str], ground_path: Path
) -> None:
    argv = ["design", str(ground_path), "--method", "pi", "--motor", "a",
            "--phase-margin", "10", "--crossover-hz", "10"]  # fmt: skip
    code, out, err = _run(capsys, *argv, "--json")
    assert code == 0, err
    entry = json.loads(out)["motors"]["a"]
    # the closed loop built here from the model and the controller's transfer function
    model = json.loads(_run(capsys, "inspect", str(ground_path), "--json")[1])["motors"]["a"]
    plant = control.tf(model["num"], model["den"], 0.01)
    ctrl = control.tf(entry["controller_num"], entry["controller_den"], 0.01)
    _, zeta, _ = control.damp(control.feedback(ctrl * plant, 1), doprint=False)
    assert np.min(zeta) < 0.1
    warnings = [line for line in err.splitlines() if line.startswith("cartctl design: warning:")]
    assert len(warnings) == 1 and "motor a" in warnings[0]
    assert f"ζ = {np.min(zeta):.3f} < 0.1" in warnings[0]
    assert entry["warnings"] and entry["warnings"][0] in warnings[0]
    # a well-damped design says nothing
    code, out, err = _run(capsys, "design", str(ground_path), "--method", "pi", "--json")
    assert code == 0
    assert "warning" not in err
    assert all(e["warnings"] == [] for e in json.loads(out)["motors"].values())


def _oe_refined_on_raw_data(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> tuple[dict, np.ndarray, np.ndarray]:
    """identify --method oe --prefilter butter --json of motor a on a physics square wave (its
    fit refined on the unfiltered data, as its note says): the motor's entry, y and u."""
    from cartctl.data.read import read_trace

    data = tmp_path / "sq.csv"
    code, _, _ = _run(capsys, "excite", "--plant", "physics", "--signal", "square",
                      "--amplitude", "10", "--out", str(data))  # fmt: skip
    assert code == 0
    code, out, _ = _run(capsys, "identify", str(data), "--method", "oe", "--prefilter", "butter",
                        "--motor", "a", "--json")  # fmt: skip
    doc = json.loads(out)["motors"]["a"]
    assert any("refined on the unfiltered data" in note for note in doc["notes"])
    trace = read_trace(data)
    return doc, trace.speed("a"), trace.voltage("a")


def test_oe_refined_on_the_unfiltered_data_has_one_covariance(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A prefiltered OE fit refined on the raw data: theta_std and the diagnostics' Σ are one
    matrix, σ̂² (JᵀJ)⁻¹ on the raw data (J by central differences of lfilter here)."""
    doc, y, u = _oe_refined_on_raw_data(capsys, tmp_path)
    cov = np.asarray(doc["theta_cov"])
    np.testing.assert_allclose(doc["theta_std"], np.sqrt(np.diag(cov)), rtol=1e-12)
    theta, nk = np.asarray(doc["theta"]), doc["nk"]

    def y_hat(th: np.ndarray) -> np.ndarray:
        return signal.lfilter(np.concatenate([np.zeros(nk), th[2:]]), np.r_[1.0, th[:2]], u)

    steps = 1e-6 * np.maximum(np.abs(theta), 1.0)
    jac = np.column_stack([
        (y_hat(theta + h * e) - y_hat(theta - h * e)) / (2.0 * h)
        for h, e in zip(steps, np.eye(theta.size), strict=True)
    ])  # fmt: skip
    err = y - y_hat(theta)
    by_hand = float(err @ err) / (y.size - theta.size) * np.linalg.inv(jac.T @ jac)
    np.testing.assert_allclose(np.diag(cov), np.diag(by_hand), rtol=1e-4)


def test_oe_refined_on_the_unfiltered_data_predicts_on_it(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """Its one-step prediction fit is on the data it was refined on (the raw data), as its
    covariance and residual RMS are; it was on the prefiltered data. An OE model has no noise
    model (H = 1), so its one-step predictor is its simulation (MATLAB's compare(data, m, 1)):
    the ARX form φ(k)ᵀθ with the OE θ is not its predictor."""
    doc, y, u = _oe_refined_on_raw_data(capsys, tmp_path)
    theta, nk = np.asarray(doc["theta"]), doc["nk"]
    assert doc["fit_prediction_percent"] == pytest.approx(_sim_fit(theta, 2, nk, y, u), abs=1e-9)


def test_oe_on_validation_data_predicts_by_its_simulation(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """With --validate-on (or --split) the fits are on the validation data: the OE row's one-step
    prediction fit is its simulation there too (it was the ARX form φ(k)ᵀθ with the OE θ)."""
    from cartctl.data.read import read_trace

    est, val = tmp_path / "est.csv", tmp_path / "val.csv"
    for path, seed in ((est, "1"), (val, "2")):
        code, _, _ = _run(capsys, "excite", "--plant", "physics", "--amplitude", "10", "--cycles",
                          "3", "--noise", "0.3", "--seed", seed, "--out", str(path))  # fmt: skip
        assert code == 0
    code, out, _ = _run(capsys, "identify", str(est), "--method", "oe", "--validate-on", str(val),
                        "--motor", "a", "--json")  # fmt: skip
    assert code == 0
    doc = json.loads(out)["motors"]["a"]
    assert doc["fit_data"] == "validation"
    trace = read_trace(val)
    y, u = trace.speed("a"), trace.voltage("a")
    theta, nk = np.asarray(doc["oe"]["theta"]), doc["oe"]["nk"]
    expected = _sim_fit(theta, 2, nk, y, u)
    assert doc["oe"]["fit_simulation_percent"] == pytest.approx(expected, abs=1e-9)
    assert doc["oe"]["fit_prediction_percent"] == pytest.approx(expected, abs=1e-9)
