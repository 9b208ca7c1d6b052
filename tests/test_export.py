"""``cartctl export --arduino``: the generated C, compiled with gcc, against the runtime controllers.

The C is compiled with a small harness that reads (reference, measured) pairs per motor and prints
the voltages; the same sequences go through the Python runtime controller built from the same file
with the steady-state estimator (what the C runs). They must agree to float32 accuracy on a step,
random measurements, long saturations (anti-windup) and non-finite inputs.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.errors import InputError
from cartctl.export.arduino import arduino_source, as_steady_state, c_float

ROOT = Path(__file__).resolve().parents[1]
CONTROLLERS = ROOT / "controllers"
GCC = shutil.which("gcc")
GXX = shutil.which("g++")
ENCODER_STEP_RAD_S = math.pi / 896 / 0.01
"""One encoder count per tick, the cart's speed resolution (rad/s)."""

HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "controller.h"

/* each line: "R" resets both motors, else "r_a y_a r_b y_b"; prints "u_a u_b" per step line */
int main(void) {
  char ra[64], ya[64], rb[64], yb[64];
  cartctl_reset_a();
  cartctl_reset_b();
  while (scanf("%63s", ra) == 1) {
    if (strcmp(ra, "R") == 0) {
      cartctl_reset_a();
      cartctl_reset_b();
      continue;
    }
    if (scanf("%63s %63s %63s", ya, rb, yb) != 3) return 1;
    float ua = cartctl_step_a(strtof(ra, NULL), strtof(ya, NULL));
    float ub = cartctl_step_b(strtof(rb, NULL), strtof(yb, NULL));
    printf("%.9g %.9g\n", (double)ua, (double)ub);
  }
  return 0;
}
"""

C_FLAGS = ["-std=c99", "-pedantic", "-O2", "-Wall", "-Wextra", "-Werror", "-Wdouble-promotion"]


def _f32(values: np.ndarray) -> list[float]:
    """Values both sides read identically: rounded to float32."""
    return [float(v) for v in np.asarray(values, dtype=np.float32)]


def _motor_sequence(rng: np.random.Generator, scale: float) -> tuple[list[float], list[float]]:
    """(reference, measured) over about 1300 ticks: step, random, saturation both ways, glitches."""
    k = np.arange(250)
    step_r = np.where(k < 20, 0.0, 10.0 * scale)
    step_y = np.where(k < 21, 0.0, 10.0 * scale * (1.0 - 0.85 ** (k - 20)))
    step_y = np.round((step_y + rng.normal(0.0, 0.1, k.size)) / ENCODER_STEP_RAD_S)
    step_y *= ENCODER_STEP_RAD_S
    rand_r = rng.uniform(-15.0, 15.0, 300)
    rand_y = rng.uniform(-20.0, 20.0, 300)
    # the wheel held still far from the reference: the command sits on the limit for 3 s,
    # then the wheel overshoots (the integral must unwind), then the same the other way
    sat_r = np.concatenate([np.full(300, 40.0), np.full(100, 5.0), np.full(250, -40.0)]) * scale
    sat_y = np.concatenate([rng.normal(0.0, 0.3, 300), np.full(100, 30.0), np.zeros(250)])
    tail_r = np.full(100, 8.0 * scale)
    tail_y = 8.0 * scale + rng.normal(0.0, 0.5, 100)
    r = np.concatenate([step_r, rand_r, sat_r, tail_r])
    y = np.concatenate([step_y, rand_y, sat_y, tail_y])
    ref, meas = _f32(r), _f32(y)
    for i in (260, 261, 700):  # a lost measurement, twice in a row, then once more
        meas[i] = math.nan
    ref[900] = math.inf  # a bad reference
    meas[1000] = -math.inf
    return ref, meas


def _script(seed: int) -> list[tuple[float, float, float, float] | None]:
    """Steps for both motors; None is a reset of both."""
    rng = np.random.default_rng(seed)
    ra, ya = _motor_sequence(rng, 1.0)
    rb, yb = _motor_sequence(rng, -0.8)
    steps: list[tuple[float, float, float, float] | None] = list(zip(ra, ya, rb, yb, strict=True))
    steps.insert(1100, None)
    return steps


def _python_voltages(controller_path: Path, script: list) -> np.ndarray:
    ctrls = build_controllers(as_steady_state(load_controller(controller_path)))
    out = []
    for step in script:
        if step is None:
            ctrls["a"].reset()
            ctrls["b"].reset()
            continue
        ra, ya, rb, yb = step
        out.append((ctrls["a"].step(ra, ya), ctrls["b"].step(rb, yb)))
    return np.array(out)


def _c_voltages(source: str, script: list, workdir: Path) -> np.ndarray:
    (workdir / "controller.h").write_text(source, encoding="utf-8")
    (workdir / "harness.c").write_text(HARNESS, encoding="utf-8")
    exe = workdir / "harness"
    subprocess.run(
        [GCC, *C_FLAGS, "-o", str(exe), str(workdir / "harness.c"), "-lm"],
        check=True,
        capture_output=True,
        text=True,
    )
    lines = ["R" if s is None else " ".join(repr(v) for v in s) for s in script]
    done = subprocess.run(
        [str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True, check=True
    )
    return np.array([[float(v) for v in line.split()] for line in done.stdout.splitlines()])


def _design(capsys: pytest.CaptureFixture[str], ground: Path, out: Path, *extra: str) -> Path:
    code = main(["design", str(ground), "--method", "pi", *extra, "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == 0, err
    return out


@pytest.fixture
def designed(
    request: pytest.FixtureRequest,
    capsys: pytest.CaptureFixture[str],
    ground_path: Path,
    tmp_path: Path,
) -> Path:
    """The controller file named by the test parameter: shipped, or designed here by the CLI."""
    name = request.param
    if name in ("pi", "poles"):
        return CONTROLLERS / f"{name}.toml"
    options = {
        "pi-back-calculation": ("--anti-windup", "back-calculation"),
        "pi-none": ("--anti-windup", "none", "--crossover-hz", "4"),
        "pi-kalman": ("--estimator", "kalman"),
    }[name]
    return _design(capsys, ground_path, tmp_path / f"{name}.toml", *options)


@pytest.mark.skipif(GCC is None, reason="gcc is not installed")
@pytest.mark.parametrize(
    "designed", ["pi", "poles", "pi-back-calculation", "pi-none", "pi-kalman"], indirect=True
)
def test_compiled_c_gives_the_runtime_controllers_voltages(designed: Path, tmp_path: Path) -> None:
    controller = load_controller(designed)
    source = arduino_source(controller)
    script = _script(seed=7)
    expected = _python_voltages(designed, script)
    got = _c_voltages(source, script, tmp_path)
    assert got.shape == expected.shape == (len(script) - 1, 2)
    limit = controller.voltage_limit_v
    # float32 against float64: 1e-4 relative, and 1e-4 of the voltage range where the voltage is
    # small (state feedback sums terms of tens of volts; the H-bridge's step is 47 mV)
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-4 * limit)
    assert np.max(np.abs(got)) == pytest.approx(limit)  # the saturation was exercised
    assert np.all(np.abs(got) <= limit)
    assert got[260, 0] == 0.0 and got[900, 0] == 0.0  # non-finite inputs give 0 V


@pytest.mark.skipif(GXX is None, reason="g++ is not installed")
@pytest.mark.parametrize("name", ["pi", "poles"])
def test_c_is_also_valid_cxx_for_the_arduino_sketch(name: str, tmp_path: Path) -> None:
    source = arduino_source(load_controller(CONTROLLERS / f"{name}.toml"))
    (tmp_path / "cartctl_controller.h").write_text(source, encoding="utf-8")
    (tmp_path / "robot.cpp").write_text(
        '#include "cartctl_controller.h"\n'
        "float tick(float r, float y) { cartctl_reset_b(); return cartctl_step_a(r, y); }\n",
        encoding="utf-8",
    )
    subprocess.run(
        [GXX, "-std=gnu++11", "-Wall", "-Wextra", "-Werror", "-fsyntax-only",
         str(tmp_path / "robot.cpp")],
        check=True, capture_output=True, text=True,
    )  # fmt: skip


def test_header_says_where_it_came_from_and_how_to_call_it() -> None:
    source = arduino_source(
        load_controller(CONTROLLERS / "serial-poles.toml"), command="cartctl export X"
    )
    head = source.split("#ifndef", 1)[0]
    for needed in (
        "cartctl export X",
        "controllers/serial-poles.toml",
        "models/ground.toml",
        "cartctl design models/ground.toml --method poles",
        "0.01 s",
        "+-12 V",
        "steady-state (fixed) gain",
        "a loop delay of 1 tick",
        "--extra-delay 2",
        "conservative",
        "readFloat(0)",
        "getSpeedMotorA()",
        "setVoltageMotorA(",
        "writeFloat(0,",
    ):
        assert needed in head, needed
    for motor in ("a", "b"):
        assert f"float cartctl_step_{motor}(float reference_rad_s, float measured_rad_s)" in source
        assert f"void cartctl_reset_{motor}(void)" in source
        assert f"}} cartctl_state_{motor}_t;" in source


def test_generated_text_is_deterministic() -> None:
    controller = load_controller(CONTROLLERS / "pi.toml")
    assert arduino_source(controller) == arduino_source(controller)


@pytest.mark.parametrize("value", [0.0, 1.0, -1.0, 0.1, -52.80429107567218, 1e-17, 3.0e38, 12.0])
def test_c_float_literals_parse_back_to_the_same_float32(value: float) -> None:
    text = c_float(value).strip("()")
    assert text.endswith("f")
    assert np.float32(float(text[:-1])) == np.float32(value)


@pytest.mark.parametrize("value", [math.inf, math.nan, 1e39])
def test_c_float_refuses_what_a_float_cannot_hold(value: float) -> None:
    with pytest.raises(InputError):
        c_float(value)


# --- the command line ----------------------------------------------------------------------------


def test_cli_prints_c_to_stdout(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["export", str(CONTROLLERS / "pi.toml"), "--arduino"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert out.startswith("// cartctl controller")
    assert "float cartctl_step_a(float reference_rad_s, float measured_rad_s) {" in out
    assert out.rstrip().endswith("#endif  /* CARTCTL_CONTROLLER_H */")


def test_cli_out_writes_the_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    target = tmp_path / "sketch" / "cartctl_controller.h"
    code = main(["export", str(CONTROLLERS / "poles.toml"), "--arduino", "--out", str(target)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert out.strip() == f"wrote {target}"
    text = target.read_text(encoding="utf-8")
    assert "cartctl_step_b" in text
    assert f"--out {target}" in text


def _one_line_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1, err
    return err


def test_cli_without_a_target_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    err = _one_line_error(capsys, ["export", str(CONTROLLERS / "pi.toml")])
    assert "--arduino" in err


def test_cli_missing_file_is_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    err = _one_line_error(capsys, ["export", str(tmp_path / "nope.toml"), "--arduino"])
    assert "not found" in err


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (lambda t: t.replace("[motors.a]", "[motors.a\n"), "TOML"),
        (lambda t: re.sub(r"^kp = .*\n", "", t, count=1, flags=re.M), "kp"),
        (lambda t: re.sub(r"^ki = .*$", "ki = -1.0", t, count=1, flags=re.M), "Ki"),
        (lambda t: t.replace("period_s = 0.01", "period_s = 0.02"), "0.02 s"),
        (lambda t: t.replace('anti_windup = "conditional"', 'anti_windup = "magic"'), "magic"),
    ],
)
def test_cli_malformed_controller_is_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, edit, expected: str
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(edit((CONTROLLERS / "pi.toml").read_text(encoding="utf-8")), encoding="utf-8")
    err = _one_line_error(capsys, ["export", str(bad), "--arduino"])
    assert expected in err
