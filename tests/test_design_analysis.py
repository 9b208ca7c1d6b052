"""``cartctl design``'s loop analysis, through the CLI on the shipped model and the shipped
controllers' own design commands: S and T peaks, the load-disturbance step, damping and natural
frequency per closed-loop pole, the terminal text and the figures.

Expectations are independent of cartctl's analysis code: python-control's ``feedback`` and
``step_response`` on a C(z) built here from Kp and Ki, ``control.damp``, and, for the controllers
with an estimator, the input sensitivity measured on cartctl's runtime controller (what the loop
runs) from its impulse response in closed loop.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import io
import json
import shlex
import tomllib
import warnings
from pathlib import Path

import control
import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.design.controllerfile import build_controllers, load_controller

ROOT = Path(__file__).resolve().parents[1]
CONTROLLERS = ROOT / "controllers"
TS = 0.01


def _shipped_argv(name: str) -> list[str]:
    """The design options that made ``controllers/<name>.toml`` (from its ``command``), without
    ``--out``, on the shipped model it was designed on."""
    doc = tomllib.loads((CONTROLLERS / f"{name}.toml").read_text(encoding="utf-8"))
    words = shlex.split(doc["command"])[2:]  # after 'cartctl design'
    i = words.index("--out")
    del words[i : i + 2]
    words[0] = str((CONTROLLERS / doc["model"]["path"]).resolve())  # the model it names
    return words


def _design(capsys: pytest.CaptureFixture[str], *argv: str) -> dict:
    code = main(["design", *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


@functools.cache
def _shipped_design_json(name: str) -> dict:
    """``cartctl design --json`` of the shipped file's own command, run once per module (several
    tests read the same design; each gets its own copy)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["design", *_shipped_argv(name), "--json"])
    assert code == 0, err.getvalue()
    return json.loads(out.getvalue())


def _shipped_design(name: str) -> dict:
    return copy.deepcopy(_shipped_design_json(name))


def _pc_loop(kp: float, ki: float, motor: str, extra: int) -> control.TransferFunction:
    """L = C·G·z^−extra with C(z) = Kp + Ki·Ts·z/(z − 1), built here by hand."""
    model = load_models(ROOT / "models" / "ground.toml").motor(motor)
    c = control.tf([kp + ki * TS, -kp], [1.0, -1.0], TS)
    g = control.tf(model.num(), model.den(), TS)
    return c * g * control.tf([1.0], [1.0] + [0.0] * extra, TS)


def _grid_peak(values: np.ndarray, freq_hz: np.ndarray) -> tuple[float, float]:
    i = int(np.argmax(values))
    return float(values[i]), float(freq_hz[i])


@pytest.mark.parametrize(("name", "extra"), [("pi", 0), ("serial-pi", 2)])
def test_pi_sensitivity_peaks_match_python_control(name: str, extra: int) -> None:
    doc = _shipped_design(name)
    shipped = load_controller(CONTROLLERS / f"{name}.toml")
    freq = np.linspace(0.005, 50.0, 40000)
    z = np.exp(2j * np.pi * freq * TS)
    for motor, e in doc["motors"].items():
        assert e["kp"] == pytest.approx(shipped.motors[motor]["kp"], rel=1e-9)
        loop = _pc_loop(e["kp"], e["ki"], motor, extra)
        s = control.feedback(1, loop)
        t = control.feedback(loop, 1)
        ms, ms_hz = _grid_peak(np.abs(s(z)), freq)
        mt, mt_hz = _grid_peak(np.abs(t(z)), freq)
        assert e["sensitivity_peak"] == pytest.approx(ms, rel=1e-5)
        assert e["sensitivity_peak_db"] == pytest.approx(20 * np.log10(ms), abs=1e-4)
        assert e["sensitivity_peak_hz"] == pytest.approx(ms_hz, abs=0.01)
        # the PI's integral action: |T| is largest, 1, at 0 Hz
        assert mt == pytest.approx(1.0, abs=1e-6) and mt_hz == pytest.approx(0.0, abs=0.01)
        assert e["complementary_peak"] == pytest.approx(1.0, abs=1e-6)
        assert e["complementary_peak_hz"] == 0.0
        assert e["complementary_peak_db"] == pytest.approx(0.0, abs=1e-4)
        assert e["sensitivity_distance"] == pytest.approx(1.0 / ms, rel=1e-5)
        # Ms is the inverse of the distance from L to −1 (python-control's own stability margin)
        with warnings.catch_warnings():  # its frequency grid meets the integrator at z = 1
            warnings.simplefilter("ignore", RuntimeWarning)
            _, _, sm, _, _, _ = control.stability_margins(loop)
        assert e["sensitivity_distance"] == pytest.approx(sm, rel=1e-3)


def _closed_loop_impulse(path: Path, motor: str, n: int = 4096) -> np.ndarray:
    """The plant input u_p = d + z^−extra·u_c for a unit impulse d at the plant input (r = 0),
    the runtime controller of the controller file ``path`` closing the loop on the model: its
    spectrum is the input sensitivity S = 1/(1 + L), and 1 − S is T."""
    shipped = load_controller(path)
    extra = int(shipped.request["extra_delay_ticks"])
    if shipped.request.get("timing_noise_std_ticks"):
        # the analysis is of the loop with the steady-state gain, which the time-varying one
        # (its process noise moved by every command change) returns to while the command holds
        from cartctl.export.arduino import as_steady_state

        shipped = as_steady_state(shipped)
    ctrl = build_controllers(shipped)[motor]
    model = load_models(shipped.model_path).motor(motor)  # the model it was designed on
    b, a = model.lfilter_coeffs()
    ctrl.reset()
    u_c, u_p, y = np.zeros(n), np.zeros(n), np.zeros(n)
    for k in range(n):
        # the ARX difference equation: y[k] = Σ b_i u_p[k−i] − Σ a_j y[k−j]
        y[k] = sum(b[i] * u_p[k - i] for i in range(1, b.size) if k - i >= 0) - sum(
            a[j] * y[k - j] for j in range(1, a.size) if k - j >= 0
        )
        u_c[k] = ctrl.step(0.0, y[k])
        u_p[k] = (1.0 if k == 0 else 0.0) + (u_c[k - extra] if k >= extra else 0.0)
    assert abs(u_p[-1]) < 1e-12  # decayed: the spectrum is the whole response
    return u_p


def _check_against_runtime(doc: dict, path: Path) -> None:
    for motor, e in doc["motors"].items():
        u_p = _closed_loop_impulse(path, motor)
        n_fft = 64 * u_p.size
        freq = np.fft.rfftfreq(n_fft, TS)
        s = np.fft.rfft(u_p, n_fft)
        ms, ms_hz = _grid_peak(np.abs(s), freq)
        mt, mt_hz = _grid_peak(np.abs(1.0 - s), freq)
        assert e["sensitivity_peak"] == pytest.approx(ms, rel=1e-4)
        assert e["sensitivity_peak_hz"] == pytest.approx(ms_hz, abs=0.01)
        assert e["complementary_peak"] == pytest.approx(mt, rel=1e-4)
        assert e["complementary_peak_hz"] == pytest.approx(mt_hz, abs=0.05)


@pytest.mark.parametrize("name", ["poles", "serial-poles"])
def test_pole_placement_sensitivity_matches_the_runtime_controller_in_closed_loop(
    name: str,
) -> None:
    _check_against_runtime(_shipped_design(name), CONTROLLERS / f"{name}.toml")


def test_pi_on_its_estimate_is_analysed_with_the_estimator_in_the_loop(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "pi-kalman.toml"
    argv = [*_shipped_argv("pi"), "--estimator", "kalman", "--out", str(path)]
    assert main(["design", *argv]) == 0
    capsys.readouterr()
    doc = _design(capsys, *argv[:-2])
    _check_against_runtime(doc, path)
    # the estimator changes the loop: Ms is not the bare PI's C·G one
    for motor, e in doc["motors"].items():
        bare = control.feedback(1, _pc_loop(e["kp"], e["ki"], motor, 0))
        z = np.exp(2j * np.pi * np.linspace(0.005, 50.0, 20000) * TS)
        assert abs(e["sensitivity_peak"] - np.max(np.abs(bare(z)))) > 1e-3


@pytest.mark.parametrize("extra", [0, 2])
def test_pi_on_its_estimate_reports_the_margins_of_that_loop(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, extra: int
) -> None:
    """The margins line of ``--estimator kalman`` is of the loop as it runs, as Ms is: the PI on
    the estimate, built here from the file's estimator (corrected first, then the PI on C·x̂,
    then the prediction with the command), python-control's margins on it."""
    path = tmp_path / "pi-kalman.toml"
    argv = [str(ROOT / "models" / "ground.toml"), "--method", "pi", "--estimator", "kalman",
            "--extra-delay", str(extra)]  # fmt: skip
    assert main(["design", *argv, "--out", str(path)]) == 0
    capsys.readouterr()
    doc = _design(capsys, *argv)
    shipped = load_controller(path)
    for motor, e in doc["motors"].items():
        est = {k: np.asarray(v, dtype=float) for k, v in shipped.motors[motor]["estimator"].items()
               if k in ("A", "B", "C", "L")}  # fmt: skip
        a, b, c, gain = est["A"], est["B"], est["C"], est["L"]
        g, q = e["kp"] + e["ki"] * TS, e["ki"] * TS  # u = g·e + I[k−1], I[k] = I[k−1] + q·e
        m = np.eye(b.size) - np.outer(gain, c)  # x̂c = m·x̂p + L·y; error e = −C·x̂c (r = 0)
        ce, de = -c @ m, -(c @ gain)
        ac = np.block(
            [[a @ m + np.outer(b, g * ce), b[:, None]], [q * ce[None, :], np.ones((1, 1))]]
        )
        bc = np.r_[a @ gain + b * g * de, q * de][:, None]
        feedback = control.ss(ac, bc, -np.r_[g * ce, 1.0][None, :], [[-g * de]], TS)  # −U/Y
        model = load_models(ROOT / "models" / "ground.toml").motor(motor)
        delay = control.tf([1.0], [1.0] + [0.0] * extra, TS)
        loop = control.tf(feedback) * control.tf(model.num(), model.den(), TS) * delay
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            gm, pm, _, wc = control.margin(loop)
        assert e["phase_margin_deg"] == pytest.approx(pm, abs=1e-6)
        assert e["crossover_hz"] == pytest.approx(wc / (2 * np.pi), rel=1e-6)
        assert e["gain_margin_db"] == pytest.approx(20 * np.log10(gm), abs=1e-6)
        assert abs(e["phase_margin_deg"] - e["target_phase_margin_deg"]) > 1.0  # not the bare PI's


@pytest.mark.parametrize(("name", "extra"), [("pi", 0), ("serial-pi", 2)])
def test_pi_rejects_a_load_step_as_python_control_simulates_it(
    capsys: pytest.CaptureFixture[str], name: str, extra: int
) -> None:
    d_v = 0.5
    doc = _design(capsys, *_shipped_argv(name), "--disturbance-v", str(d_v))
    model_file = load_models(ROOT / "models" / "ground.toml")
    for motor, e in doc["motors"].items():
        dist = e["disturbance"]
        model = model_file.motor(motor)
        g = control.tf(model.num(), model.den(), TS)
        c = control.tf([e["kp"] + e["ki"] * TS, -e["kp"]], [1.0, -1.0], TS)
        delay = control.tf([1.0], [1.0] + [0.0] * extra, TS)
        # d enters at the plant input, the command reaches it after the extra delay
        t, y = control.step_response(control.feedback(g, c * delay), T=np.arange(200) * TS)
        y = d_v * np.squeeze(y)
        i = int(np.argmax(np.abs(y)))
        assert dist["step_v"] == d_v
        assert dist["peak_deviation_rad_s"] == pytest.approx(y[i], rel=1e-9)
        assert dist["peak_time_s"] == pytest.approx(t[i], abs=1e-12)
        band = 0.02 * abs(y[i])
        outside = np.flatnonzero(np.abs(y) > band)
        assert dist["recovery_time_s"] == pytest.approx(t[outside[-1] + 1], abs=1e-12)
        # integral action: no steady-state deviation (final-value theorem), u settles at −d
        assert abs(dist["final_deviation_rad_s"]) < 1e-9
        assert dist["final_voltage_v"] == pytest.approx(-d_v, abs=1e-9)
        # and the deviation is the open loop's static one reduced by the loop
        assert abs(dist["peak_deviation_rad_s"]) < d_v * model.dc_gain()


@pytest.mark.parametrize("name", ["pi", "poles", "serial-poles"])
def test_damping_and_frequency_of_each_closed_loop_pole_as_control_damp(name: str) -> None:
    doc = _shipped_design(name)
    for e in doc["motors"].values():
        table = e["closed_loop_pole_table"]
        poles = np.array([complex(re, im) for re, im in e["closed_loop_poles"]])
        assert [complex(r["re"], r["im"]) for r in table] == list(poles)  # same poles, same order
        # control.damp on a system with exactly these poles: s = ln z / Ts
        system = control.tf([1.0], np.real(np.poly(poles)), TS)
        wn, zeta, p = control.damp(system, doprint=False)
        for row in table:
            j = int(np.argmin(np.abs(p - complex(row["re"], row["im"]))))
            assert row["damping"] == pytest.approx(zeta[j], abs=1e-9)
            assert row["freq_hz"] == pytest.approx(wn[j] / (2 * np.pi), rel=1e-9)
        # a hand check of one pole: ζ = −ln|z| / |ln z|
        z = poles[-1]
        s = np.log(z) / TS
        assert table[-1]["damping"] == pytest.approx(-s.real / abs(s), rel=1e-12)


def test_text_shows_the_analysis_with_units_and_3_significant_figures(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # the example of docs/design.md (the PI shipped before the actuation timing entered its choice)
    readme_pi = [str(ROOT / "models" / "ground.toml"), "--method", "pi", "--phase-margin", "65",
                 "--crossover-hz", "4"]  # fmt: skip
    assert main(["design", *readme_pi]) == 0
    text = capsys.readouterr().out
    assert "Kp = 0.178 V/(rad/s), Ki = 12.4 V/rad" in text
    assert "sensitivity peak Ms = 1.49 (3.44 dB) at 9.55 Hz" in text
    assert "complementary peak Mt = 1.00 (0.00 dB) at 0 Hz" in text
    assert "1.00 V load step at the plant input: peak 1.40 rad/s at 40 ms" in text
    assert "natural frequency (Hz)" in text and "damping ζ" in text
    assert "steady-state error 0.0 rad/s" in text  # 1.8e-15 rad/s of floating-point noise
    assert "e-1" not in text  # no raw tiny numbers
    assert main(["design", *_shipped_argv("poles")]) == 0
    text = capsys.readouterr().out
    assert "V/(rad/s) and 1 on the disturbance estimate, Ki = 0 V/rad, Kr = " in text
    k_line = next(line for line in text.splitlines() if line.startswith("motor a: K = ["))
    gains = k_line.split("[")[1].split("]")[0].split(", ")
    # one precision for the list: 3 significant figures for the largest
    assert len({len(g.split(".")[1]) for g in gains}) == 1, k_line
    largest = max(gains, key=lambda g: abs(float(g)))
    assert len(largest.lstrip("-").replace(".", "").lstrip("0")) == 3, k_line


def test_json_keeps_the_contract_and_adds_the_analysis() -> None:
    doc = _shipped_design("poles")
    for e in doc["motors"].values():
        assert {"closed_loop_poles", "phase_margin_deg", "sensitivity_peak", "step"} <= set(e)
        assert all(len(p) == 2 for p in e["closed_loop_poles"])
        added = {"sensitivity_peak_db", "sensitivity_peak_hz", "complementary_peak",
                 "complementary_peak_db", "complementary_peak_hz", "disturbance",
                 "closed_loop_pole_table"}  # fmt: skip
        assert added <= set(e)
        assert set(e["closed_loop_pole_table"][0]) == {"re", "im", "damping", "freq_hz"}


def _texts_inside(fig) -> None:
    """Everything drawn lies inside the figure, and each axes' own notes inside that axes: the
    figure as its last draw laid it out (the report's ``savefig``), measured by an Agg renderer."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()  # savefig left the figure without a canvas
    tight = fig.get_tightbbox(renderer)  # inches, what is drawn
    width, height = fig.get_size_inches()
    assert tight.x0 >= -0.01 and tight.y0 >= -0.01, tight
    assert tight.x1 <= width + 0.01 and tight.y1 <= height + 0.01, tight
    for ax in fig.axes:
        for text in ax.texts:
            ext, box = text.get_window_extent(renderer), ax.bbox
            assert box.x0 <= ext.x0 and ext.x1 <= box.x1, text.get_text()
            assert box.y0 <= ext.y0 and ext.y1 <= box.y1, text.get_text()
        legend = ax.get_legend()
        if legend is not None:
            ext, box = legend.get_window_extent(renderer), ax.bbox
            assert box.x0 <= ext.x0 and ext.x1 <= box.x1 and box.y0 <= ext.y0 and ext.y1 <= box.y1


def test_report_writes_both_figures_with_all_text_inside(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from matplotlib.figure import Figure

    saved: dict[str, Figure] = {}  # each figure the report saves, by its file's name
    original = Figure.savefig

    def keep(self: Figure, path: Path, *args: object, **kwargs: object) -> None:
        original(self, path, *args, **kwargs)
        saved[Path(path).name] = self

    monkeypatch.setattr(Figure, "savefig", keep)
    out = tmp_path / "report"
    assert main(["design", *_shipped_argv("pi"), "--report", str(out)]) == 0
    capsys.readouterr()
    for m in "ab":
        for stem in ("design", "analysis"):
            png = out / f"{stem}_{m}.png"
            assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert png.stat().st_size < 200_000
            _texts_inside(saved[png.name])  # the figure in that file, as it was laid out for it


@pytest.mark.parametrize("value", ["0", "13", "nan"])
def test_a_bad_disturbance_is_one_line(capsys: pytest.CaptureFixture[str], value: str) -> None:
    code = main(["design", *_shipped_argv("pi"), "--disturbance-v", value])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "--disturbance-v" in err
