"""Controller files that know their loop and cannot lie: loop delay and plant kind, the model path
relative to the file, and C(z) checked against the gains on load (the shipped files and edited
copies of them, through the command line)."""

from __future__ import annotations

import json
import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.data.read import read_trace
from cartctl.design.controllerfile import load_controller
from cartctl.errors import DataFileError

ROOT = Path(__file__).resolve().parents[1]
CONTROLLERS = ROOT / "controllers"
SHIPPED = ["pi.toml", "poles.toml", "serial-pi.toml", "serial-poles.toml"]


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(code: int, err: str) -> str:
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def _extra_delay(command: str) -> int:
    found = re.search(r"--extra-delay (\d+)", command)
    return int(found.group(1)) if found else 0


# -- loop delay and plant kind ----------------------------------------------------------------


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_files_say_the_loop_they_are_for(name: str, ground_path: Path) -> None:
    raw = tomllib.loads((CONTROLLERS / name).read_text(encoding="utf-8"))
    nk = {m.nk for m in load_models(ground_path).motors.values()}
    assert nk == {2}  # the report's ground model
    expected = 2 - 1 + _extra_delay(raw["command"])  # nk − 1 + extra delay
    if name == "poles.toml":  # the timing model, nk = 1, for the same loop: --loop-delay 1
        timing = {
            m.nk for m in load_models(ground_path.parent / "ground-timing.toml").motors.values()
        }
        assert timing == {1} and "--loop-delay 1" in raw["command"]
        assert raw["model"]["path"] == "../models/ground-timing.toml"
    else:
        assert raw["model"]["path"] == "../models/ground.toml"  # from controllers/
    assert raw["loop_delay_ticks"] == expected
    assert raw["plant_kind"] == ("onboard" if expected == 1 else "serial")
    loaded = load_controller(CONTROLLERS / name)
    assert loaded.loop_delay_ticks == expected
    assert name.startswith("serial-") == (loaded.loop_site == "serial")


def test_a_file_without_loop_delay_gets_it_from_its_model(workdir: Path) -> None:
    text = (workdir / "controllers" / "serial-pi.toml").read_text(encoding="utf-8")
    old = re.sub(r"^(loop_delay_ticks|plant_kind) = .*\n", "", text, flags=re.M)
    old = old.replace('path = "../models/ground.toml"', 'path = "models/ground.toml"')
    (workdir / "controllers" / "old.toml").write_text(old, encoding="utf-8")
    # an older cartctl wrote the model path from the working directory: still found from there
    assert load_controller("controllers/old.toml").loop_delay_ticks == 2 - 1 + 2  # nk − 1 + extra


def test_a_file_without_loop_delay_and_without_its_model_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    text = (workdir / "controllers" / "pi.toml").read_text(encoding="utf-8")
    old = re.sub(r"^(loop_delay_ticks|plant_kind) = .*\n", "", text, flags=re.M)
    (workdir / "old.toml").write_text(old, encoding="utf-8")  # ../models/ from here: no such file
    code, _, err = _cli(capsys, "run", "--fast", "--controller", "old.toml", "--rerun", "off")
    line = _one_line_error(code, err)
    assert "loop_delay_ticks" in line and "models/ground.toml" in line


def test_a_plant_kind_against_the_loop_delay_is_refused(tmp_path: Path) -> None:
    text = (CONTROLLERS / "pi.toml").read_text(encoding="utf-8")
    assert 'plant_kind = "onboard"' in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('plant_kind = "onboard"', 'plant_kind = "serial"'), "utf-8")
    with pytest.raises(
        DataFileError, match="plant_kind = 'serial' contradicts loop_delay_ticks = 1"
    ):
        load_controller(bad)


def test_design_out_refuses_motors_with_different_delays(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, ground_path: Path
) -> None:
    text = ground_path.read_text(encoding="utf-8")
    head, _, motor_b = text.partition("[motors.b]")
    assert "nk = 2" in motor_b
    mixed = tmp_path / "mixed.toml"
    mixed.write_text(head + "[motors.b]" + motor_b.replace("nk = 2", "nk = 3", 1), "utf-8")
    code, _, err = _cli(capsys, "design", str(mixed), "--method", "pi", "--out",
                        str(tmp_path / "c.toml"))  # fmt: skip
    line = _one_line_error(code, err)
    assert "nk = 2" in line and "nk = 3" in line
    assert not (tmp_path / "c.toml").exists()
    code, _, err = _cli(capsys, "design", str(mixed), "--method", "pi", "--motor", "b", "--out",
                        str(tmp_path / "b.toml"))  # fmt: skip
    assert code == 0, err
    assert load_controller(tmp_path / "b.toml").loop_delay_ticks == 3 - 1


# -- the model path ---------------------------------------------------------------------------


def test_model_path_is_relative_to_the_controller_file(
    capsys: pytest.CaptureFixture[str], workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = workdir / "deep" / "er" / "c.toml"
    code, _, err = _cli(capsys, "design", "models/ground.toml", "--method", "pi", "--out",
                        "deep/er/c.toml")  # fmt: skip
    assert code == 0, err
    raw = tomllib.loads(out.read_text(encoding="utf-8"))
    assert raw["model"]["path"] == "../../models/ground.toml"
    elsewhere = workdir / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    loaded = load_controller(out)
    assert os.path.samefile(loaded.model_path, workdir / "models" / "ground.toml")
    assert not loaded.model_changed()
    code, _, err = _cli(capsys, "run", "--fast", "--controller", str(out), "--model",
                        "../models/ground.toml", "--duration", "0.5", "--rerun", "off", "--json")  # fmt: skip
    assert code == 0, err
    assert "changed" not in err


# -- C(z) against the gains -------------------------------------------------------------------


@pytest.mark.parametrize("name", ["pi.toml", "serial-pi.toml"])
def test_shipped_pi_num_den_are_its_gains(name: str) -> None:
    raw = tomllib.loads((CONTROLLERS / name).read_text(encoding="utf-8"))
    ts = raw["period_s"]
    for entry in raw["motors"].values():
        kp, ki = entry["kp"], entry["ki"]
        np.testing.assert_allclose(entry["controller_num"], [kp + ki * ts, -kp], rtol=1e-12)
        assert entry["controller_den"] == [1.0, -1.0]


@pytest.mark.parametrize("name", ["poles.toml", "serial-poles.toml"])
def test_shipped_poles_num_den_close_the_loop_on_the_placed_poles(
    name: str, ground_path: Path
) -> None:
    raw = tomllib.loads((CONTROLLERS / name).read_text(encoding="utf-8"))
    extra = raw["request"]["extra_delay_ticks"]
    models = load_models(load_controller(CONTROLLERS / name).model_path)  # the one designed on
    for motor, entry in raw["motors"].items():
        model = models.motor(motor)
        plant_den = np.polymul(model.den(), [1.0] + [0.0] * extra)  # z^d more delay
        # feedback C = −U/Y = num/den: the loop's characteristic polynomial
        char = np.polyadd(np.polymul(entry["controller_den"], plant_den),
                          np.polymul(entry["controller_num"], model.num()))  # fmt: skip
        # each placed pole is a root (to 1e-3: the estimator's cluster of poles near z = 0 makes
        # the roots of this order-13 polynomial ill-conditioned at the 1e-6 level)
        roots = np.roots(char)
        for re_, im in entry["closed_loop_poles"]:
            assert np.min(np.abs(roots - complex(re_, im))) < 1e-3


def _edit_kp(text: str, factor: float) -> tuple[str, float, float]:
    """Scale motor a's kp in a PI file's text (its controller_num left alone)."""
    found = re.search(r"^kp = (.*)$", text, flags=re.M)
    assert found
    kp = float(found.group(1))
    edited = text[: found.start(1)] + repr(kp * factor) + text[found.end(1) :]
    return edited, kp, kp * factor


@pytest.mark.filterwarnings("always::cartctl.errors.DataWarning")  # the CLI prints it
def test_pi_gains_against_num_are_refused_then_forced(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    text = (workdir / "controllers" / "pi.toml").read_text(encoding="utf-8")
    edited, kp, new_kp = _edit_kp(text, 2.0)
    (workdir / "controllers" / "edited.toml").write_text(edited, encoding="utf-8")
    raw = tomllib.loads(edited)
    ki, ts = raw["motors"]["a"]["ki"], raw["period_s"]
    stored = raw["motors"]["a"]["controller_num"]
    argv = ["run", "--fast", "--controller", "controllers/edited.toml", "--reference", "step:10",
            "--duration", "1", "--rerun", "off", "--json", "--name", "forced"]  # fmt: skip
    code, out, err = _cli(capsys, *argv)
    line = _one_line_error(code, err)
    assert "[motors.a] controller_num" in line
    assert f"{stored[1]:.10g}" in line  # the stored −Kp ...
    assert f"{new_kp + ki * ts:.10g}" in line and f"{-new_kp:.10g}" in line  # ... and the gains'
    assert out == ""
    assert not (workdir / "logs").exists()

    code, out, err = _cli(capsys, *argv, "--force")
    assert code == 0, err
    warning = err.strip().splitlines()
    assert len(warning) == 1 and "warning" in warning[0] and "--force" in warning[0]
    assert "controller_num" in warning[0]
    trace = read_trace(json.loads(out)["trace"])
    first = int(np.flatnonzero(trace.column("reference_a"))[0])
    # at the step's first tick y = 0, e = 10: u = (Kp + Ki·Ts)·10 with the edited Kp (it runs)
    assert trace.column("voltage_a")[first] == pytest.approx((new_kp + ki * ts) * 10.0)
    assert trace.column("voltage_a")[first] != pytest.approx((kp + ki * ts) * 10.0)


def test_poles_gains_against_num_are_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    text = (workdir / "controllers" / "poles.toml").read_text(encoding="utf-8")
    found = re.search(r"^K = \[\n    ([^,]+),", text, flags=re.M)
    assert found
    k0 = float(found.group(1))
    edited = text[: found.start(1)] + repr(k0 * 1.1) + text[found.end(1) :]
    (workdir / "controllers" / "edited.toml").write_text(edited, encoding="utf-8")
    code, _, err = _cli(capsys, "run", "--fast", "--controller", "controllers/edited.toml",
                        "--rerun", "off")  # fmt: skip
    line = _one_line_error(code, err)
    assert "[motors.a] controller_num" in line and "K, Ki, the estimator" in line
