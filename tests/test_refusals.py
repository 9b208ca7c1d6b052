"""Absurd inputs get one line and exit 2, and nothing is written: output names, durations."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.cli import main
from cartctl.commands.options import file_stem


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's usage errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("name", ["../../x", "sub/x", "/tmp/x", "..", ".", ""])
def test_a_name_with_a_folder_is_refused_before_anything_is_written(
    capsys: pytest.CaptureFixture[str], workdir: Path, name: str
) -> None:
    code, out, err = _run(capsys, "run", "--fast", "--name", name, "--rerun", "off")
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cartctl run: error: argument --name")
    assert "without a folder" in lines[0]
    assert not (workdir / "logs").exists()
    assert (
        not (workdir.parent / "x.csv").exists() and not (workdir.parent.parent / "x.csv").exists()
    )


def test_monitor_refuses_the_same_names(capsys: pytest.CaptureFixture[str], workdir: Path) -> None:
    code, _, err = _run(capsys, "monitor", "virtual", "--name", "../x", "--duration", "0.1")
    assert code == 2 and "argument --name" in err and len(err.strip().splitlines()) == 1


@given(st.text(max_size=40))
@settings(max_examples=300, deadline=None)
def test_a_name_is_either_refused_or_stays_in_its_folder(text: str) -> None:
    folder = Path("/srv/logs")
    try:
        stem = file_stem(text)
    except argparse.ArgumentTypeError as exc:
        message = str(exc)
        stem = None
    if stem is None:
        assert "\n" not in message  # one line, whatever the name holds
        return
    path = folder / f"{stem}.csv"
    assert path.parent == folder and ".." not in path.relative_to(folder).parts


@pytest.mark.parametrize(
    "argv",
    [
        ("run", "--fast", "--duration", "1e9"),
        ("run", "--fast", "--duration", "86401"),
        ("run", "--fast", "--duration", "nan"),
        ("run", "--fast", "--duration", "-1"),
        ("tune", "models/ground.toml", "--method", "pi", "--duration", "1e9"),
        (
            "excite",
            "--plant",
            "sim",
            "--signal",
            "prbs",
            "--amplitude",
            "5",
            "--duration",
            "1e9",
            "--out",
            "x.csv",
        ),
        (
            "excite",
            "--plant",
            "sim",
            "--signal",
            "square",
            "--amplitude",
            "5",
            "--cycles",
            "100000000",
            "--out",
            "x.csv",
        ),
        (
            "excite",
            "--plant",
            "sim",
            "--signal",
            "multisine",
            "--amplitude",
            "5",
            "--cycles",
            "100000000",
            "--out",
            "x.csv",
        ),
        ("monitor", "virtual", "--duration", "1e9"),
    ],
)
def test_durations_beyond_a_day_are_refused_in_one_line(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: tuple[str, ...]
) -> None:
    code, out, err = (
        _run(capsys, *argv, "--rerun", "off") if argv[0] == "run" else _run(capsys, *argv)
    )
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"cartctl {argv[0]}: error:")
    assert "24 h" in lines[0]
    assert not (workdir / "logs").exists() and not (workdir / "x.csv").exists()


def _trace_file(path: Path, volts_a: float | None, volts_b: float | None) -> Path:
    """500 ticks with constant voltages (None: a square wave) and some speed."""
    import numpy as np

    from cartctl.data import Trace, write_trace

    n = 500
    t = np.arange(n) * 0.01
    square = np.where((np.arange(n) // 100) % 2 == 0, 6.0, -6.0)
    columns = {
        "time_s": t,
        "voltage_a": square if volts_a is None else np.full(n, volts_a),
        "voltage_b": square if volts_b is None else np.full(n, volts_b),
        "speed_a": np.sin(t),
        "speed_b": np.cos(t),
    }
    write_trace(Trace.from_columns(columns), path)
    return path


@pytest.mark.parametrize("output", [("--out", "m.toml"), ("--json",), ("--report", "rep")])
@pytest.mark.parametrize(
    ("volts", "says"),
    [((0.0, 0.0), "motor a: its voltage is zero"), ((5.0, 0.0), "a constant 5 V")],
)
def test_identify_without_excitation_says_which_motor_and_writes_nothing(
    capsys: pytest.CaptureFixture[str], workdir: Path, output: tuple[str, ...], volts, says: str
) -> None:
    data = _trace_file(workdir / "flat.csv", *volts)
    code, out, err = _run(capsys, "identify", str(data), *output)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "cartctl identify: error: no motor has excitation"
    )
    assert says in lines[0] and "motor b: its voltage is zero" in lines[0]
    assert not (workdir / "m.toml").exists() and not (workdir / "rep").exists()


def test_identify_one_motor_never_driven(capsys: pytest.CaptureFixture[str], workdir: Path) -> None:
    data = _trace_file(workdir / "a_only.csv", None, 0.0)
    code, _, err = _run(capsys, "identify", str(data), "--motor", "b", "--out", "m.toml")
    assert code == 2 and "motor b has no excitation" in err and len(err.strip().splitlines()) == 1
    assert not (workdir / "m.toml").exists()
    code, out, err = _run(capsys, "identify", str(data), "--json")  # both: a alone, b noted
    assert code == 0 and "motor b skipped: no excitation" in err
    assert list(json.loads(out)["motors"]) == ["a"]


@pytest.mark.parametrize(
    "argv",
    [("run", "--plant", "serial:/dev/ttyNOPE", "--rerun", "off"),
     ("monitor", "serial:/dev/ttyNOPE", "--duration", "1", "--rerun", "off")],
)  # fmt: skip
def test_a_port_that_does_not_exist_is_a_user_mistake(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: tuple[str, ...]
) -> None:
    code, _, err = _run(capsys, *argv)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "serial port /dev/ttyNOPE does not exist" in lines[0]
    assert "serial ports present" in lines[0]
    assert not (workdir / "logs").exists()


def test_an_ill_conditioned_placement_is_one_readable_line(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    code, _, err = _run(capsys, "design", "models/ground.toml", "--method", "poles",
                        "--settling-time", "1e6")  # fmt: skip
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "ill-conditioned" in lines[0]
    assert "[" not in lines[0] and "array" not in lines[0]
