"""Absurd inputs get one line and exit 2, and nothing is written: output names, durations."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.cli import main
from cartctl.cli.commands.options import file_stem


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

    from cartctl.data.trace import Trace, write_trace

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


def test_a_port_another_program_holds_is_refused_in_one_line(
    capsys: pytest.CaptureFixture[str], workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A monitor left running on the port: a second cartctl shared its bytes with it (the run
    lost frames, the monitor stopped with 'cable pulled?'). The port is now opened exclusively."""
    import os

    import serial

    from cartctl.link import cart_link

    monkeypatch.setattr(cart_link, "LEGACY_LISTEN_S", 0.05)  # the old code's second listen
    master, slave = os.openpty()
    port = os.ttyname(slave)
    holder = serial.Serial(port, 500000, exclusive=True)  # as cartctl monitor holds it
    try:
        code, _, err = _run(capsys, "run", "--plant", f"serial:{port}", "--rerun", "off",
                            "--connect-timeout", "0.05")  # fmt: skip
    finally:
        holder.close()
        os.close(master)
        os.close(slave)
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1, err
    assert f"serial port {port} is in use by another program" in lines[0], lines[0]
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


# -- inputs outside physics ----------------------------------------------------------------------


def test_data_with_voltages_beyond_the_supply_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    import numpy as np

    from cartctl.data.trace import Trace, write_trace

    n = 300
    volts = np.where(np.arange(n) < 150, 6.0, 1e300)
    write_trace(Trace.from_columns({"time_s": np.arange(n) * 0.01, "voltage_a": volts,
                                    "voltage_b": np.zeros(n), "speed_a": np.zeros(n),
                                    "speed_b": np.zeros(n)}), workdir / "mv.csv")  # fmt: skip
    for command in (("identify", "mv.csv"), ("validate", "models/ground.toml", "mv.csv")):
        code, out, err = _run(capsys, *command)
        assert code == 2 and out == ""
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "mv.csv, line 152" in lines[0]
        assert "1e+300 V, beyond the cart's ±12 V supply" in lines[0]


def _uncontrolled_reach() -> float:
    """What motor a of the report's ground model reaches at 12 V: 12 (a + b) / (1 + c + d)."""
    c, d, a, b = -0.9356, 0.2173, 0.6466, -0.07751
    return 12.0 * (a + b) / (1.0 + c + d)


@pytest.mark.filterwarnings("always::cartctl.errors.DataWarning")  # the CLI prints it
def test_a_reference_beyond_reach_is_refused_and_one_near_it_flagged(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    reach = _uncontrolled_reach()  # 24.2 rad/s
    code, _, err = _run(capsys, "run", "--fast", "--reference", "step:1e308", "--rerun", "off")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"it reaches about {reach:.3g}" in err and not (workdir / "logs").exists()
    code, _, err = _run(capsys, "run", "--fast", "--reference", f"step:{1.2 * reach:.1f}",
                        "--duration", "1", "--rerun", "off")  # fmt: skip
    warned = [line for line in err.splitlines() if "saturates" in line]
    assert code == 0 and len(warned) == 1 and "motor a" in warned[0] and "motor b" in warned[0]
    code, _, err = _run(capsys, "run", "--fast", "--reference", f"step:{0.9 * reach:.1f}",
                        "--duration", "1", "--rerun", "off")  # fmt: skip
    assert code == 0 and "saturates" not in err


def test_a_gain_that_saturates_on_one_count_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    text = (workdir / "controllers" / "pi.toml").read_text(encoding="utf-8")
    (workdir / "controllers" / "huge.toml").write_text(
        re.sub(r"^kp = .*$", "kp = 1e300", text, count=1, flags=re.M), encoding="utf-8"
    )
    code, _, err = _run(capsys, "run", "--fast", "--controller", "controllers/huge.toml")
    assert code == 2
    lines = err.strip().splitlines()
    # one count per tick is 2π/1792/0.01 = 0.3506 rad/s: 12 V / 0.3506 rad/s = 34.2 V per rad/s
    assert len(lines) == 1 and "kp = 1e+300" in lines[0] and "below 34.2" in lines[0]
    assert not (workdir / "logs").exists()


# an ARX model (na = 2, nb = 3, nk = 1) commissioned on the physics cart's air preset: its third
# input term puts a zero near the origin that pole placement answers with large gains on the
# estimator's states (|K| up to 48 V per rad/s), though the controller barely answers the speed
AIR3_THETA = [-0.24448299334785445, -0.08661246025730783, 0.3235761691391532,
              0.8804609306853032, 0.2043903172696777]  # fmt: skip
QUANTUM = 2 * np.pi / 1792 / 0.01  # one encoder count per tick (rad/s)


def _reaction_from_file(path: Path, motor: str = "a") -> float:
    """|u[0]| (V per rad/s) of the stored C_fb(z) = controller_num/controller_den (measured speed
    to voltage) for a unit impulse of the speed: its answer in the tick the change arrives."""
    import tomllib

    from scipy import signal

    entry = tomllib.loads(path.read_text(encoding="utf-8"))["motors"][motor]
    impulse = np.zeros(8)
    impulse[0] = 1.0
    return abs(float(signal.lfilter(entry["controller_num"], entry["controller_den"], impulse)[0]))


def test_a_state_feedback_is_judged_by_its_answer_to_the_measured_speed(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    rows = "\n".join(f"[motors.{m}]\ntheta = {AIR3_THETA}\nna = 2\nnb = 3\nnk = 1\n" for m in "ab")
    model = workdir / "models" / "air3.toml"
    model.write_text(f'format = "cartctl-model/2"\nperiod_s = 0.01\nloop_delay_ticks = 1\n\n'
                     f"{rows}", encoding="utf-8")  # fmt: skip
    code, _, err = _run(capsys, "design", str(model), "--method", "poles", "--settling-time",
                        "0.1", "--overshoot", "1.1", "--out", "air3-poles.toml")  # fmt: skip
    assert code == 0, err
    import tomllib

    gains = tomllib.loads((workdir / "air3-poles.toml").read_text(encoding="utf-8"))
    # an entry of K alone would put the whole 12 V on one count (12 / 0.3506 = 34.2 V per rad/s)
    assert max(abs(k) for k in gains["motors"]["a"]["K"]) * QUANTUM > 12.0
    # but the controller answers a count in its tick with well under a volt
    assert _reaction_from_file(workdir / "air3-poles.toml") * QUANTUM < 1.0
    code, out, err = _run(capsys, "run", "--fast", "--controller", "air3-poles.toml", "--model",
                          str(model), "--duration", "1", "--rerun", "off", "--json")  # fmt: skip
    assert code == 0, err
    assert json.loads(out)["motors"]["a"]["overshoot_percent"] < 5.0


def test_a_state_feedback_that_switches_on_one_count_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    shipped = workdir / "controllers" / "poles.toml"
    assert _reaction_from_file(shipped) * QUANTUM < 12.0
    text = shipped.read_text(encoding="utf-8")
    # 1e5 on K's first entry: with the estimator's L, K·L puts thousands of volts on one count
    switching = re.sub(r"(\[motors\.a\]\nK = \[\n    )[^,]+,", r"\g<1>1e5,", text, count=1)
    import tomllib

    entry = tomllib.loads(switching)["motors"]["a"]
    assert abs(np.dot(entry["K"], entry["estimator"]["L"])) * QUANTUM > 12.0
    (workdir / "controllers" / "switch.toml").write_text(switching, encoding="utf-8")
    code, _, err = _run(capsys, "run", "--fast", "--controller", "controllers/switch.toml",
                        "--rerun", "off")  # fmt: skip
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1
    assert (
        "[motors.a] K with the estimator's L answers one encoder count" in lines[0]
        and "switch" in lines[0]
    )
    assert not (workdir / "logs").exists()


@pytest.fixture
def unstable_model(workdir: Path) -> Path:
    text = (workdir / "models" / "ground.toml").read_text(encoding="utf-8")
    # motor a: z² − 2.1 z + 1.05 has roots 1.05 ± 0.224: outside the unit circle
    path = workdir / "models" / "unstable.toml"
    path.write_text(text.replace("[-0.9356, 0.2173,", "[-2.1, 1.05,"), encoding="utf-8")
    return path


def test_an_unstable_model_is_refused_by_run_unless_allowed(
    capsys: pytest.CaptureFixture[str], workdir: Path, unstable_model: Path
) -> None:
    pole = max(abs(r) for r in np.roots([1.0, -2.1, 1.05]))
    code, _, err = _run(capsys, "run", "--fast", "--model", str(unstable_model), "--rerun", "off")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"motor a's model is unstable (pole at |z| = {pole:.4g})" in err
    code, out, err = _run(capsys, "run", "--fast", "--model", str(unstable_model), "--rerun",
                          "off", "--allow-unstable", "--duration", "30", "--json")  # fmt: skip
    assert code == 1  # a plant fault: the simulation ran away, the files hold the run so far
    assert "the simulated motor a ran away" in err
    summary = json.loads(out)
    assert summary["ticks"] < 3000


def test_validate_says_the_model_is_unstable(
    capsys: pytest.CaptureFixture[str], workdir: Path, unstable_model: Path
) -> None:
    data = _trace_file(workdir / "sq.csv", None, None)
    code, out, err = _run(capsys, "validate", str(unstable_model), str(data), "--json")
    assert code == 0
    doc = json.loads(out)
    assert (
        doc["motors"]["a"]["stable"] is False
        and doc["motors"]["a"]["fit_simulation_percent"] is None
    )
    assert doc["motors"]["b"]["stable"] is True
    warned = [line for line in err.splitlines() if "unstable" in line]
    assert len(warned) == 1 and warned[0].startswith("cartctl validate: warning:")


# -- messages that state facts ---------------------------------------------------------------------


def _spaced_trace(path: Path, steps_s: np.ndarray) -> Path:
    from cartctl.data.trace import Trace, write_trace

    t = np.concatenate([[0.0], np.cumsum(steps_s)])
    n = t.size
    volts = np.where((np.arange(n) // 50) % 2 == 0, 5.0, -5.0)
    write_trace(Trace.from_columns({"time_s": t, "voltage_a": volts, "voltage_b": np.zeros(n),
                                    "speed_a": volts * 2.0, "speed_b": np.zeros(n)}), path)  # fmt: skip
    return path


def test_spacing_warning_tells_jitter_from_missing_rows(tmp_path: Path) -> None:
    from cartctl.data.read import read_trace
    from cartctl.errors import DataWarning

    jitter = np.full(300, 0.01)
    jitter[100] = 0.012  # one 12 ms step: the clock, not a lost frame
    with pytest.warns(DataWarning, match="no row is missing, but the sample clock jitters"):
        read_trace(_spaced_trace(tmp_path / "j.csv", jitter))
    gaps = np.full(300, 0.01)
    gaps[[50, 200]] = 0.02  # two frames lost
    gaps[120] = 0.03  # two more in a row
    with pytest.warns(DataWarning, match=r"about 4 row\(s\) are missing"):
        read_trace(_spaced_trace(tmp_path / "g.csv", gaps))


def _qrc6(path: Path, labels: list[str]) -> Path:
    head = "QGPIORecord, QRC v6.0.2, 14-03-2024 @ 10:05:31, Ubuntu, x86_64\n"
    rows = [", ".join(["Time", *labels])]
    for k in range(20):
        rows.append(", ".join([str(5000 + 10 * k)] + [str(float(k % 3))] * len(labels)))
    path.write_text(head + "\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("labels", "hint"),
    [
        (["Error", "Ref", "voltA", "speedA"] + [f"FloatIn{i}" for i in range(4, 12)],
         "--map voltage_a=voltA,speed_a=speedA"),
        (["Error", "Ref", "x", "y"] + [f"FloatIn{i}" for i in range(4, 12)],
         "--map voltage_a=<label>,speed_a=<label> (no label says which channel is which)"),
    ],
)  # fmt: skip
def test_the_map_hint_never_guesses_by_position(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, labels: list[str], hint: str
) -> None:
    code, _, err = _run(capsys, "convert", str(_qrc6(tmp_path / "log.csv", labels)))
    assert code == 2 and hint in err and "=Error" not in err and len(err.strip().splitlines()) == 1


def test_delay_auto_says_when_the_data_cannot_tell(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A speed that is noise, whatever the voltage: every delay explains it equally (badly)."""
    from cartctl.data.trace import Trace, write_trace

    rng = np.random.default_rng(11)
    n = 20000
    volts = rng.choice([-6.0, 6.0], n)
    speed = rng.normal(0.0, 1.0, n)
    write_trace(Trace.from_columns({"time_s": np.arange(n) * 0.01, "voltage_a": volts,
                                    "voltage_b": np.zeros(n), "speed_a": speed,
                                    "speed_b": np.zeros(n)}), tmp_path / "noise.csv")  # fmt: skip
    code, out, err = _run(capsys, "identify", str(tmp_path / "noise.csv"), "--delay", "auto",
                          "--motor", "a")  # fmt: skip
    assert code == 2 and out == ""
    assert "--delay auto cannot tell" in err and "give --delay N" in err
    assert len(err.strip().splitlines()) == 1
