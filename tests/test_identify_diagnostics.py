"""Identification diagnostics through ``cartctl identify``: residual tests, the order table,
validation data, Bode bands and compared models; expectations computed here with numpy and scipy
(np.correlate, np.linalg.lstsq, scipy.signal.lfilter and freqz)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from cartctl.cli import main
from cartctl.data.trace import Trace, write_trace

THETA = [-0.9356, 0.2173, 0.6466, -0.07751]  # the report's ground model, motor A
Z99 = 2.576


def _simulate(seed: int, n: int = 3000, noise: float = 0.3, nk: int = 2):
    """ARX data A(q) y = B(q) u[k − nk] + e with white e: the structure's own noise model."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-6.0, 6.0], size=n // 5 + 1), 5)[:n]
    e = rng.normal(0.0, noise, n)
    a = [1.0, THETA[0], THETA[1]]
    y = signal.lfilter([0.0] * nk + THETA[2:], a, u) + signal.lfilter([1.0], a, e)
    return u, y


def _write(path: Path, u: np.ndarray, y: np.ndarray) -> Path:
    z = np.zeros_like(u)
    write_trace(Trace(np.arange(u.size) * 0.01, u, z, y, z), path)
    return path


def _data(
    tmp_path: Path, seed: int = 1, name: str = "d.csv", **kw
) -> tuple[Path, np.ndarray, np.ndarray]:
    u, y = _simulate(seed, **kw)
    # the CSV holds rounded numbers: read back what the command reads
    path = _write(tmp_path / name, u, y)
    from cartctl.data.read import read_trace

    trace = read_trace(path)
    return path, trace.voltage("a"), trace.speed("a")


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    code, out, err = _run(capsys, *argv, "--json")
    assert code == 0, err
    return json.loads(out)


def _regression(y: np.ndarray, u: np.ndarray, na: int, nb: int, nk: int, start: int):
    rows = range(start, y.size)
    phi = np.array(
        [[-y[k - i] for i in range(1, na + 1)] + [u[k - nk - j] for j in range(nb)] for k in rows]
    )
    return phi, y[start:]


def _nrmse(y: np.ndarray, y_hat: np.ndarray) -> float:
    return 100.0 * (1.0 - np.linalg.norm(y - y_hat) / np.linalg.norm(y - y.mean()))


# -- residual tests --------------------------------------------------------------------------


def _expected_residual_test(y, u, na, nb, nk, lags=25):
    start = max(na, nk + nb - 1)
    phi, target = _regression(y, u, na, nb, nk, start)
    theta = np.linalg.lstsq(phi, target, rcond=None)[0]
    e = target - phi @ theta
    e = e - e.mean()
    uc = u[start:] - u[start:].mean()
    n = e.size
    full_e = np.correlate(e, e, "full")  # index n − 1 + τ holds Σ e(k + τ) e(k)
    auto = full_e[n : n + lags] / full_e[n - 1]
    full_eu = np.correlate(e, uc, "full")
    cross = full_eu[n - 1 - lags : n + lags] / np.sqrt(np.dot(e, e) * np.dot(uc, uc))
    full_u = np.correlate(uc, uc, "full")
    r_u = full_u[n - 1 : n + lags] / full_u[n - 1]
    r_e = np.concatenate([[1.0], auto])
    p = 1.0 + 2.0 * np.sum(r_e[1:] * r_u[1:])
    return auto, cross, Z99 / np.sqrt(n), Z99 * np.sqrt(max(p, 1.0) / n), n  # floored at white


def test_residuals_of_the_right_structure_pass_and_match_numpy(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path, u, y = _data(tmp_path)
    doc = _json(capsys, "identify", str(path), "--motor", "a", "--delay", "2")
    res = doc["motors"]["a"]["residuals"]
    auto, cross, bound, cross_bound, n = _expected_residual_test(y, u, 2, 2, 2)
    np.testing.assert_allclose(res["auto"], auto, atol=1e-9)
    np.testing.assert_allclose(res["cross"], cross, atol=1e-9)
    assert res["bound_99"] == pytest.approx(bound)
    assert res["cross_bound_99"] == pytest.approx(cross_bound)
    assert res["n_samples"] == n
    assert res["auto_lags"] == 25 and res["cross_lags"] == 51
    assert res["auto_outside"] == int(np.sum(np.abs(auto) > bound))
    assert res["cross_outside"] == int(np.sum(np.abs(cross) > cross_bound))
    assert res["auto_max_abs"] == pytest.approx(np.max(np.abs(auto)))
    assert res["white"] and res["independent"]
    code, out, _ = _run(capsys, "identify", str(path), "--motor", "a")
    assert code == 0
    assert "lags outside" in out and ": white;" in out and "independent of the input" in out


@pytest.mark.parametrize(
    ("options", "orders"),
    [(["--na", "1", "--nb", "1"], (1, 1, 2)), (["--delay", "3"], (2, 2, 3))],
)
def test_residuals_of_a_wrong_structure_fail(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, options: list[str], orders: tuple
) -> None:
    path, u, y = _data(tmp_path)
    res = _json(capsys, "identify", str(path), "--motor", "a", *options)["motors"]["a"]["residuals"]
    auto, cross, bound, cross_bound, _ = _expected_residual_test(y, u, *orders)
    np.testing.assert_allclose(res["auto"], auto, atol=1e-9)
    assert np.sum(np.abs(auto) > bound) > 2  # far more than chance: 25 lags at 1 % each
    assert np.sum(np.abs(cross) > cross_bound) > 3
    assert not res["white"] and not res["independent"]
    _, out, _ = _run(capsys, "identify", str(path), "--motor", "a", *options)
    assert "NOT white" in out and "CORRELATED with the input" in out


def test_exact_data_gives_negligible_residuals_and_no_verdict(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path, _, _ = _data(tmp_path, noise=0.0)
    res = _json(capsys, "identify", str(path), "--motor", "a")["motors"]["a"]["residuals"]
    assert res["negligible"] and res["rms_rad_s"] < 1e-9
    code, out, _ = _run(capsys, "identify", str(path), "--motor", "a")
    assert code == 0 and "the residual tests say nothing" in out
    assert "e-1" not in out  # standard deviations at rounding level print as 0, not 1e-16


# -- order table -----------------------------------------------------------------------------


def test_order_table_matches_least_squares_by_hand(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path, u, y = _data(tmp_path)
    spec = "na=1:2,nb=1:2,nk=1:3"
    rows = _json(capsys, "identify", str(path), "--motor", "a", "--orders", spec)["motors"]["a"][
        "orders"
    ]
    assert [(r["na"], r["nb"], r["nk"]) for r in rows] == [
        (na, nb, nk) for na in (1, 2) for nb in (1, 2) for nk in (1, 2, 3)
    ]
    start = max(max(na, nk + nb - 1) for na in (1, 2) for nb in (1, 2) for nk in (1, 2, 3))
    for row in rows:
        phi, target = _regression(y, u, row["na"], row["nb"], row["nk"], start)
        theta = np.linalg.lstsq(phi, target, rcond=None)[0]
        n, d = target.size, phi.shape[1]
        v = np.mean((target - phi @ theta) ** 2)
        assert row["n_equations"] == n and row["params"] == d
        assert row["loss"] == pytest.approx(v, rel=1e-9)
        assert row["aic"] == pytest.approx(n * math.log(v) + 2 * d, rel=1e-9)
        assert row["fpe"] == pytest.approx(v * (1 + d / n) / (1 - d / n), rel=1e-9)
        sim = signal.lfilter([0.0] * row["nk"] + list(theta[row["na"] :]),
                             [1.0, *theta[: row["na"]]], u)  # fmt: skip
        assert row["fit_percent"] == pytest.approx(_nrmse(y, sim), abs=1e-6)
        assert row["fit_on"] == "estimation"
    best = next(r for r in rows if r["best_aic"])
    assert (best["na"], best["nb"], best["nk"]) == (2, 2, 2)  # the true structure
    assert best["aic"] == min(r["aic"] for r in rows)
    code, out, _ = _run(capsys, "identify", str(path), "--motor", "a", "--orders", spec)
    assert code == 0
    assert "loss V (rad/s)²" in out and "AIC (–)" in out and "FPE (rad/s)²" in out
    line = next(ln for ln in out.splitlines() if ln.split()[:3] == ["2", "2", "2"])
    assert "AIC" in line


def test_default_grid_and_bad_specs(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path, _, _ = _data(tmp_path, n=600)
    rows = _json(capsys, "identify", str(path), "--motor", "a", "--orders")["motors"]["a"]["orders"]
    assert len(rows) == 36
    for spec in ("nx=1:2", "na=3:1", "na=a", "na=1:60", "na=0:50,nb=1:50,nk=0:50"):
        code, out, err = _run(capsys, "identify", str(path), "--orders", spec)
        assert code == 2 and out == ""
        assert err.startswith("cartctl identify: error: --orders") and "Traceback" not in err


# -- validation data -------------------------------------------------------------------------


def test_validate_on_reports_fits_on_the_other_experiment(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    est, u, y = _data(tmp_path, seed=1, name="est.csv")
    val, u_v, y_v = _data(tmp_path, seed=2, name="val.csv")
    doc = _json(capsys, "identify", str(est), "--motor", "a", "--validate-on", str(val),
                "--orders", "na=2,nb=2,nk=1:3")  # fmt: skip
    a = doc["motors"]["a"]
    phi, target = _regression(y, u, 2, 2, 2, 3)
    theta = np.linalg.lstsq(phi, target, rcond=None)[0]
    np.testing.assert_allclose(a["theta"], theta, atol=1e-9)
    sim = signal.lfilter([0.0, 0.0, *theta[2:]], [1.0, *theta[:2]], u_v)
    assert a["fit_data"] == "validation"
    assert a["fit_simulation_percent"] == pytest.approx(_nrmse(y_v, sim), abs=1e-6)
    phi_v, target_v = _regression(y_v, u_v, 2, 2, 2, 3)
    assert a["fit_prediction_percent"] == pytest.approx(_nrmse(target_v, phi_v @ theta), abs=1e-6)
    assert a["residuals"]["n_samples"] == target_v.size
    assert all(r["fit_on"] == "validation" for r in a["orders"])
    best = next(r for r in a["orders"] if r["best_fit"])
    assert best["nk"] == 2


def test_split_estimates_on_the_start_and_validates_on_the_rest(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path, u, y = _data(tmp_path)
    a = _json(capsys, "identify", str(path), "--motor", "a", "--split", "0.7")["motors"]["a"]
    m = round(0.7 * u.size)
    phi, target = _regression(y[:m], u[:m], 2, 2, 2, 3)
    theta = np.linalg.lstsq(phi, target, rcond=None)[0]
    np.testing.assert_allclose(a["theta"], theta, atol=1e-9)
    sim = signal.lfilter([0.0, 0.0, *theta[2:]], [1.0, *theta[:2]], u[m:])
    assert a["fit_simulation_percent"] == pytest.approx(_nrmse(y[m:], sim), abs=1e-6)
    code, out, _ = _run(capsys, "identify", str(path), "--motor", "a", "--split", "0.7")
    assert "on the validation data" in out
    for bad in ("1.5", "0", "0.001"):
        code, out, err = _run(capsys, "identify", str(path), "--split", bad)
        assert code == 2 and err.startswith("cartctl identify: error: --split")
    with pytest.raises(SystemExit) as stop:
        main(["identify", str(path), "--split", "0.5", "--validate-on", str(path)])
    assert stop.value.code == 2 and "not allowed with" in capsys.readouterr().err


# -- Bode bands ------------------------------------------------------------------------------


def _band(capsys, tmp_path: Path, noise: float) -> dict:
    path, _, _ = _data(tmp_path, name=f"n{noise}.csv", noise=noise)
    return _json(capsys, "identify", str(path), "--motor", "a")["motors"]["a"]


def test_bode_bands_grow_with_noise_and_hold_the_true_response(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    quiet, loud = _band(capsys, tmp_path, 0.1), _band(capsys, tmp_path, 1.0)
    widths = []
    for entry in (quiet, loud):
        band = entry["bode_band"]
        lo, hi = np.array(band["mag_db_2sigma"])
        widths.append(np.mean(hi - lo))
        f = np.array(band["freq_hz"])
        _, h = signal.freqz([0.0, 0.0, *THETA[2:]], [1.0, *THETA[:2]], worN=2 * np.pi * f * 0.01)
        mag = 20 * np.log10(np.abs(h))
        assert np.mean((mag >= lo) & (mag <= hi)) >= 0.8
        lo1, hi1 = np.array(band["mag_db_1sigma"])
        assert np.all(lo <= lo1) and np.all(hi1 <= hi)
        p_lo, p_hi = np.array(band["phase_deg_2sigma"])
        phase = np.degrees(np.unwrap(np.angle(h)))
        assert np.mean((phase >= p_lo) & (phase <= p_hi)) >= 0.8
        # the covariance's diagonal is the standard deviations the fit reports
        np.testing.assert_allclose(
            np.sqrt(np.diag(entry["theta_cov"])), entry["theta_std"], rtol=1e-6
        )
    assert widths[1] > 3 * widths[0]


# -- compared models -------------------------------------------------------------------------


def test_compared_models_and_the_residual_figure_in_the_table_json_and_report(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path, u, y = _data(tmp_path)
    out_dir = tmp_path / "rep"
    doc = _json(capsys, "identify", str(path), "--motor", "a", "--compare", "models/air.toml",
                "models/ground.toml", "--report", str(out_dir))  # fmt: skip
    compared = doc["motors"]["a"]["compared"]
    assert set(compared) == {"models/air.toml", "models/ground.toml"}
    from cartctl.data.modelfile import load_models

    air = load_models("models/air.toml").motors["a"]
    sim = signal.lfilter([0.0] * air.nk + list(air.b), [1.0, *air.ar], u)
    assert compared["models/air.toml"]["fit_simulation_percent"] == pytest.approx(
        _nrmse(y, sim), abs=1e-6
    )
    sim = signal.lfilter([0.0, 0.0, *THETA[2:]], [1.0, *THETA[:2]], u)
    assert compared["models/ground.toml"]["fit_simulation_percent"] == pytest.approx(
        _nrmse(y, sim), abs=1e-6
    )
    summary = (out_dir / "summary.md").read_text()
    assert "| air (models/air.toml) |" in summary and "| ground (models/ground.toml) |" in summary
    png = out_dir / "residuals_a.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "![residuals_a](residuals_a.png)" in summary and "Residual tests" in summary
    code, out, _ = _run(
        capsys, "identify", str(path), "--motor", "a", "--compare", "models/air.toml"
    )
    assert code == 0
    row = next(ln for ln in out.splitlines() if ln.strip().startswith("air (file)"))
    assert f"{compared['models/air.toml']['fit_simulation_percent']:.2f}" in row
