"""The Python API: the guide's example (docs/python-api.md) runs as written, and each function agrees
with the CLI."""

from __future__ import annotations

import inspect
import json
import re
import sys
from pathlib import Path

import control
import matplotlib
import numpy as np
import pytest

import cartctl
from cartctl.cli import build_parser, main

matplotlib.use("Agg")
ROOT = Path(__file__).resolve().parents[1]


API_PAGE = ROOT / "docs" / "python-api.md"


def _example_blocks() -> tuple[str, str]:
    """The guide's API example and the printed summary shown after it."""
    text = API_PAGE.read_text(encoding="utf-8")
    match = re.search(r"<!-- api-example[^>]*-->\s*```python\n(.*?)```.*?```(?:text)?\n(.*?)```",
                      text, flags=re.S)  # fmt: skip
    assert match, f"{API_PAGE} has no API example"
    return match.group(1), match.group(2)


@pytest.fixture
def square(capsys: pytest.CaptureFixture[str], workdir: Path) -> Path:
    code = main(["excite", "--plant", "physics", "--signal", "square", "--amplitude", "10",
                 "--cycles", "3", "--out", "logs/square.csv"])  # fmt: skip
    capsys.readouterr()
    assert code == 0
    return workdir / "logs" / "square.csv"


def test_the_guide_example_runs_in_an_empty_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The example makes its own data: nothing in the folder before, the files after."""
    monkeypatch.chdir(tmp_path)
    assert not any(tmp_path.iterdir())
    code, shown = _example_blocks()
    namespace: dict[str, object] = {}
    exec(compile(code, str(API_PAGE), "exec"), namespace)
    printed = capsys.readouterr().out
    assert (tmp_path / "models" / "mine.toml").is_file()
    assert (tmp_path / "controllers" / "mine.toml").is_file()
    assert (tmp_path / "step.png").stat().st_size > 10_000
    run = namespace["run"]
    a = run.summary["motors"]["a"]  # type: ignore[attr-defined]
    assert a["overshoot_percent"] < 10.0 and a["settling_time_s"] is not None
    # the summary the guide shows has the layout print(run) gives: its title and its columns
    title, headers = shown.splitlines()[:2]
    assert title.split(", plant")[0] in printed and headers in printed.splitlines()
    assert len(printed) < 3 * 2_000  # three short summaries and a transfer function


def test_excite_records_what_the_cli_records(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    assert main(["excite", "--plant", "physics", "--signal", "prbs", "--amplitude", "6",
                 "--duration", "2", "--motor", "b", "--out", "logs/prbs.csv"]) == 0  # fmt: skip
    capsys.readouterr()
    cli = cartctl.load_trace("logs/prbs.csv")
    api = cartctl.excite(plant="physics", signal="prbs", amplitude_v=6, duration_s=2, motor="b")
    assert len(api) == len(cli) == 200
    np.testing.assert_allclose(api.voltage_b, cli.voltage_b, atol=1e-9)
    np.testing.assert_allclose(api.speed_b, cli.speed_b, atol=1e-6)
    assert not np.any(api.voltage_a) and np.max(np.abs(api.voltage_b)) == pytest.approx(6.0)


@pytest.mark.parametrize(
    ("options", "named"),
    [({"plant": "virtual"}, "virtual"), ({"amplitude_v": 13.0}, "amplitude_v"),
     ({"motor": "c"}, "motor"), ({"duration_s": 2.0}, "duration_s")],
)  # fmt: skip
def test_excite_refuses_in_one_line(options: dict, named: str) -> None:
    with pytest.raises(cartctl.errors.InputError, match=named) as refused:
        cartctl.excite(**options)
    assert "\n" not in str(refused.value)


def test_identify_gives_the_cli_theta_and_a_python_control_tf(
    capsys: pytest.CaptureFixture[str], square: Path
) -> None:
    ident = cartctl.identify(square)
    assert main(["identify", str(square), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    # the loop the trace was recorded in (its .meta.toml, written by excite) goes into the model
    assert ident.result.loop_delay_ticks == printed["loop_delay_ticks"] == 1
    assert "loop delay 1 tick," in repr(ident)
    cli = printed["motors"]
    for m in "ab":
        np.testing.assert_allclose(ident[m].theta, cli[m]["theta"], rtol=1e-12)
        np.testing.assert_allclose(ident[m].theta_std, cli[m]["theta_std"], rtol=1e-12)
        tf = ident[m].tf
        assert isinstance(tf, control.TransferFunction) and tf.dt == pytest.approx(0.01)
        c, d, a, b = ident[m].theta
        # the report's H(z) = (a z + b) / (z³ + c z² + d z): compare the frequency responses
        z = np.exp(1j * 2 * np.pi * np.array([0.5, 3.0, 20.0]) * 0.01)
        expected = (a * z + b) / (z**3 + c * z**2 + d * z)
        np.testing.assert_allclose(tf(z), expected, rtol=1e-9)


def test_design_and_simulate_agree_with_design_and_run(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    design = cartctl.design_poles("models/ground.toml", settling_time_s=0.045,
                                  process_noise_std_v=0.05, bias_drift_std_v=0.06)  # fmt: skip
    assert main(["design", "models/ground.toml", "--method", "poles", "--settling-time", "0.045",
                 "--process-noise-v", "0.05", "--bias-drift-v", "0.06", "--json"]) == 0  # fmt: skip
    cli = json.loads(capsys.readouterr().out)["motors"]
    for m in "ab":
        np.testing.assert_allclose(design[m]["K"], cli[m]["K"], rtol=1e-12)
    path = design.save(workdir / "controllers" / "api-poles.toml")
    run = cartctl.simulate(design, plant="sim", reference="step:8", duration_s=1.5)
    assert main(["run", "--fast", "--controller", str(path), "--reference", "step:8",
                 "--duration", "1.5", "--rerun", "off", "--json", "--name", "api"]) == 0  # fmt: skip
    summary = json.loads(capsys.readouterr().out)
    trace = cartctl.load_trace(summary["trace"])
    np.testing.assert_allclose(run.columns["voltage_a"], trace.voltage_a, rtol=0, atol=1e-9)
    assert run.summary["ticks"] == summary["ticks"] == len(trace)
    assert run.failure is None


@pytest.mark.parametrize(
    ("method", "argv", "options"),
    [("pi", ["--phase-margin", "60", "--crossover-hz", "4", "--voltage-limit", "10", "--step", "8"],
      {"phase_margin_deg": 60, "crossover_hz": 4, "voltage_limit_v": 10, "step_rad_s": 8}),
     ("poles", ["--settling-time", "1", "--overshoot", "2"],
      {"settling_time_s": 1, "overshoot_percent": 2}),
     ("pi", ["--crossover-hz", "4.5", "--extra-delay", "1", "--step", "8"],  # numpy's numbers
      {"crossover_hz": np.float64(4.5), "extra_delay_ticks": np.int64(1),
       "step_rad_s": np.float32(8)})],
)  # fmt: skip
def test_design_save_writes_the_file_design_out_writes(
    method: str, argv: list[str], options: dict, workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Whole numbers given to the API are the floats the command line parses (8.0, not 8), numpy's
    numbers plain ones (not --crossover-hz 'np.float64(4.5)'), and the header's command writes the
    file again (its --out); the creation time aside."""
    out = "controllers/same.toml"
    args = ["design", "models/ground.toml", "--method", method, *argv, "--out", out]
    monkeypatch.setattr(sys, "argv", ["cartctl", *args])
    assert main(args) == 0
    cli = Path(out).read_text(encoding="utf-8")
    design = cartctl.design_pi if method == "pi" else cartctl.design_poles
    design("models/ground.toml", **options).save(out)
    api = Path(out).read_text(encoding="utf-8")
    created = re.compile(r"^created = .*$", flags=re.M)
    assert created.sub("", api) == created.sub("", cli)


def test_simulate_with_runs_defaults_gives_runs_numbers(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    """The guide names the defaults where simulate differs from run (2 s on the model designed
    on; run: 5 s on models/ground.toml): given run's, a design on another model gives the same."""
    simulate = inspect.signature(cartctl.simulate).parameters
    run_defaults = build_parser("run").parse_args(["run"])
    assert (simulate["duration_s"].default, run_defaults.duration) == (2.0, 5.0)
    assert run_defaults.model == "models/ground.toml"
    guide = " ".join(API_PAGE.read_text(encoding="utf-8").split())
    assert "`simulate` runs 2 s on the model the controller was designed on" in guide
    assert "`--duration 5` on `--model models/ground.toml`" in guide
    cartctl.design_pi("models/air.toml", crossover_hz=4).save("controllers/air.toml")
    api = cartctl.simulate("controllers/air.toml", duration_s=5, model="models/ground.toml")
    assert main(["run", "--fast", "--controller", "controllers/air.toml", "--rerun", "off",
                 "--json", "--name", "air"]) == 0  # fmt: skip
    cli = json.loads(capsys.readouterr().out)
    assert api.summary["ticks"] == cli["ticks"] == 501
    for m in "ab":
        for key, value in api.summary["motors"][m].items():
            assert cli["motors"][m][key] == pytest.approx(value, rel=1e-9, abs=1e-12), key


def test_to_dataframe_gives_the_columns(workdir: Path) -> None:
    pd = pytest.importorskip("pandas")  # the dev extra installs it
    run = cartctl.simulate("controllers/pi.toml", duration_s=0.3)
    frame = run.to_dataframe()
    assert isinstance(frame, pd.DataFrame) and list(frame.columns) == list(run.columns)
    assert len(frame) == 31  # 30 ticks and the stop row
    np.testing.assert_array_equal(frame["voltage_a"].to_numpy(), run.columns["voltage_a"])


def test_to_dataframe_without_pandas_says_how_to_get_it(
    workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = cartctl.simulate("controllers/pi.toml", duration_s=0.3)
    monkeypatch.setitem(sys.modules, "pandas", None)  # as if not installed: import fails
    with pytest.raises(cartctl.errors.InputError, match=r"cartctl\[pandas\]") as refused:
        run.to_dataframe()
    assert "\n" not in str(refused.value)


def test_import_cartctl_stays_light() -> None:
    """The API loads on first use: ``import cartctl`` (the CLI's first import) pulls no numpy."""
    import subprocess

    code = "import sys, cartctl; print('numpy' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"
