"""The command line: its subcommands, their JSON output, and one-line errors with exit code 2.

Tests call ``main(argv)`` in-process; one test runs the installed console script end to end.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from cartctl.cli import main
from cartctl.data.read import read_trace

CONTRACT_COMMANDS = (
    "excite",
    "identify",
    "inspect",
    "validate",
    "linearity",
    "design",
    "run",
    "review",
)


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's --help and usage errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def test_help_lists_every_contract_command(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "--help")
    assert code == 0
    for name in CONTRACT_COMMANDS:
        assert name in out


@pytest.mark.parametrize("name", CONTRACT_COMMANDS)
def test_every_command_has_help(capsys: pytest.CaptureFixture[str], name: str) -> None:
    code, out, _ = _run(capsys, name, "--help")
    assert code == 0
    assert f"cartctl {name}" in out


def test_inspect_json_reproduces_equation_12(
    capsys: pytest.CaptureFixture[str], ground_path: Path
) -> None:
    code, out, err = _run(capsys, "inspect", str(ground_path), "--json")
    assert code == 0
    assert err == ""
    doc = json.loads(out)
    assert doc["Ts"] == 0.01
    a = doc["motors"]["a"]
    assert a["stable"] is True
    assert a["dc_gain"] == pytest.approx(2.02, abs=0.005)
    delay = [p for p in a["poles"] if p["kind"] == "delay"]
    contract = ("re", "im", "kind", "freq_hz", "damping")  # the JSON pole keys; more may follow
    assert [{k: p[k] for k in contract} for p in delay] == [
        {"re": 0.0, "im": 0.0, "kind": "delay", "freq_hz": None, "damping": None}
    ]
    freqs = sorted(p["freq_hz"] for p in a["poles"] if p["kind"] == "pole")
    assert freqs == pytest.approx([10.8, 13.5], abs=0.06)
    assert set(a["poles"][0]) >= set(contract)
    assert [z["kind"] for z in a["zeros"]] == ["zero"]
    assert a["num"] == [0.6466, -0.07751]
    assert a["den"] == [1.0, -0.9356, 0.2173, 0.0]
    assert set(doc["motors"]) == {"a", "b"}


def test_inspect_table_is_readable(capsys: pytest.CaptureFixture[str], air_path: Path) -> None:
    code, out, _ = _run(capsys, "inspect", str(air_path))
    assert code == 0
    assert "motor a" in out
    assert "delay" in out
    assert "12.43" in out  # report §3.1: 12.4344 Hz
    assert "39.91" in out  # and 39.9032 Hz
    assert "DC gain" in out


def _report_eq12(voltage: np.ndarray, motor: str) -> np.ndarray:
    """Equation 12 simulated independently of cartctl's model classes."""
    num, den = {
        "a": ([0.6466, -0.07751], [1.0, -0.9356, 0.2173, 0.0]),
        "b": ([0.6886, -0.1068], [1.0, -0.9082, 0.1968, 0.0]),
    }[motor]
    return signal.lfilter([0.0, 0.0, *num], den, voltage)


def test_excite_sim_square_equals_equation_12(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path
) -> None:
    out_csv = tmp_path / "x.csv"
    code, out, err = _run(
        capsys, "excite", "--plant", "sim", "--model", str(ground_path), "--signal", "square",
        "--amplitude", "10", "--out", str(out_csv),
    )  # fmt: skip
    assert code == 0, err
    assert "wrote" in out
    trace = read_trace(out_csv)
    assert len(trace) == 1500
    assert set(np.unique(trace.voltage_a)) == {-10.0, 0.0, 10.0}
    for motor in ("a", "b"):
        np.testing.assert_allclose(
            trace.speed(motor), _report_eq12(trace.voltage(motor), motor), atol=1e-9
        )


@pytest.mark.parametrize("signal_name", ["step", "prbs", "multisine", "chirp"])
def test_excite_other_signals_one_motor(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path, signal_name: str
) -> None:
    out_csv = tmp_path / f"{signal_name}.csv"
    code, _, err = _run(
        capsys, "excite", "--model", str(ground_path), "--signal", signal_name, "--amplitude", "6",
        "--motor", "b", "--duration", "4", "--out", str(out_csv),
    )  # fmt: skip
    assert code == 0, err
    trace = read_trace(out_csv)
    assert np.all(trace.voltage_a == 0.0)
    assert np.max(np.abs(trace.voltage_b)) == pytest.approx(6.0)


@pytest.mark.parametrize("motor", ["a", "b"])
def test_excite_one_motor_model_drives_its_motor(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path, motor: str
) -> None:
    """A one-motor model file drives its motor, the other at 0 V (it was refused: the sim plant
    wanted both motors' models); the motor it lacks cannot be driven."""
    import dataclasses

    import cartctl
    from cartctl.data.modelfile import load_models, save_models

    models = load_models(ground_path)
    one = save_models(dataclasses.replace(models, motors={motor: models.motor(motor)}),
                      tmp_path / "one.toml")  # fmt: skip
    out_csv = tmp_path / "x.csv"
    argv = ["excite", "--model", str(one), "--motor", motor, "--amplitude", "10", "--cycles", "1"]
    code, _, err = _run(capsys, *argv, "--out", str(out_csv))
    assert code == 0, err
    trace = read_trace(out_csv)
    np.testing.assert_allclose(trace.speed(motor), _report_eq12(trace.voltage(motor), motor),
                               atol=1e-9)  # fmt: skip
    other = "b" if motor == "a" else "a"
    assert np.all(trace.speed(other) == 0.0) and np.all(trace.voltage(other) == 0.0)
    api = cartctl.excite(plant="sim", model=one, motor=motor, cycles=1)
    np.testing.assert_array_equal(api.speed(motor), trace.speed(motor))
    for driven in (other, "both"):
        code, out, err = _run(capsys, *argv[:4], driven, *argv[5:], "--out", str(out_csv))
        assert code == 2 and out == "" and f"lacks ['{other}']" in err
        assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["inspect", "missing.toml"], "model file not found: missing.toml"),
        (["excite", "--amplitude", "20", "--out", "x.csv"], "beyond the cart's ±12 V supply"),
        (
            ["excite", "--amplitude", "5", "--model", "nope.toml", "--out", "x.csv"],
            "model file not found",
        ),
        (
            ["excite", "--plant", "moon", "--amplitude", "5", "--out", "x.csv"],
            "unknown plant 'moon'",
        ),
        (
            ["excite", "--signal", "sawtooth", "--amplitude", "5", "--out", "x.csv"],
            "invalid choice",
        ),
        (["excite", "--amplitude", "ten", "--out", "x.csv"], "invalid float value"),
    ],
)
def test_user_mistakes_give_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    argv: list[str],
    message: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    code, out, err = _run(capsys, *argv)
    assert code == 2
    assert out == ""
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err


@pytest.mark.parametrize(
    ("argv", "prog"),
    [(["run", "--bogus"], "cartctl run"), (["design", "m.toml", "--method", "pi", "x"],
      "cartctl design"), (["review", "a.csv", "--nope", "1"], "cartctl review")],
)  # fmt: skip
def test_unrecognised_arguments_name_their_subcommand(
    capsys: pytest.CaptureFixture[str], argv: list[str], prog: str
) -> None:
    code, out, err = _run(capsys, *argv)
    assert code == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert line.startswith(f"{prog}: error: unrecognized arguments: ")
    assert line.endswith(f"(see '{prog} --help')")


@pytest.mark.skipif(shutil.which("cartctl") is None, reason="console script not installed")
def test_console_script_end_to_end(tmp_path: Path) -> None:
    proc = subprocess.run(
        ["cartctl", "inspect", "nope.toml"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == "cartctl inspect: error: model file not found: nope.toml"


DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("time_s,voltage_a,voltage_b,speed_a\n0,1,0,0\n", "speed_b"),  # a missing column
        (
            "time_s,voltage_a,voltage_b,speed_a,speed_b\n0,1,0,0,0\n0.01,nan,0,0,0\n",
            "line 3",
        ),  # NaN
        ("", "empty"),
    ],
)
def test_bad_csv_gives_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, content: str, message: str
) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(content)
    code, out, err = _run(capsys, "convert", str(path))
    assert code == 2
    assert out == ""
    assert "bad.csv" in err
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_missing_data_file(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = _run(capsys, "convert", "no_such_file.csv")
    assert code == 2
    assert err.strip() == "cartctl convert: error: trace file not found: no_such_file.csv"


def test_convert_qrc_log_with_map(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out_csv = tmp_path / "qrc.csv"
    code, _, err = _run(
        capsys, "convert", str(DATA / "qrc6_sample.csv"), "--map", "voltage_a=voltA,speed_a=speedA",
        "--out", str(out_csv), "--json",
    )  # fmt: skip
    assert code == 0, err
    trace = read_trace(out_csv)
    assert trace.time_s[0] == 0.0
    assert trace.period_s == pytest.approx(0.01)
    assert trace.voltage_a.min() == -4.5


def test_bad_map_option(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = _run(capsys, "convert", str(DATA / "qrc6_sample.csv"), "--map", "voltage_a")
    assert code == 2
    assert "--map" in err
    assert len(err.strip().splitlines()) == 1


def test_a_command_line_builds_only_its_command_with_the_same_options() -> None:
    """``cartctl run …`` builds the run parser alone; it must be the full parser's run parser."""
    from cartctl.cli import build_parser, command_name
    from cartctl.cli.commands import COMMANDS

    full = build_parser()
    full_sub = {a.dest: a for a in full._actions}["command"].choices
    assert [command_name(m) for m in COMMANDS] == list(full_sub)
    for name, whole in full_sub.items():
        alone = {a.dest: a for a in build_parser(name)._actions}["command"].choices
        assert list(alone) == [name]
        options = [(a.option_strings, a.dest, a.default, a.help) for a in alone[name]._actions]
        assert options == [(a.option_strings, a.dest, a.default, a.help) for a in whole._actions]
