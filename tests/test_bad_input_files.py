"""Malformed files and out-of-range values a user may give, through the command line: one line
``cartctl COMMAND: error: …`` naming the file or option, exit 2, no traceback, nothing written
(test_bad_inputs.py holds the table of wrong paths, kinds of file and options)."""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path
from typing import Any

import pytest

import cartctl
from cartctl.cli import main
from cartctl.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
GROUND = (ROOT / "models" / "ground.toml").read_text(encoding="utf-8")
POLES = (ROOT / "controllers" / "poles.toml").read_text(encoding="utf-8")
PI = (ROOT / "controllers" / "pi.toml").read_text(encoding="utf-8")


def _edit(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


FILES = {  # name: content, each a file a user could have edited by hand
    "prov.toml": _edit(GROUND, "[provenance]\n", "provenance = 'notes'\n[other]\n"),
    "data.toml": _edit(GROUND, "data = []", "data = 'run.csv'"),
    "trace.csv": "time_s,voltage_a,voltage_b,speed_a,speed_b\n0,0,0,0,0\n0.01,5,5,0,0\n",
    "zero.toml": _edit(GROUND, "0.6466, -0.07751", "0.0, 0.0"),
    "v9.toml": _edit(GROUND, "cartctl-model/2", "cartctl-model/9"),
    "controllers/pi.toml": PI,
    "controllers/kp.toml": _edit(PI, "kp = 0.17191709625355944", "kp = 'fast'"),
    "controllers/K.toml": _edit(POLES, "K = [\n    0.10498612817563781,", "K = [\n    'x',"),
    "controllers/A.toml": _edit(POLES, "        0.7947558602793067,\n", ""),
    "controllers/v9.toml": _edit(POLES, "cartctl-controller/2", "cartctl-controller/9"),
    "one.csv": "time_s,voltage_a,voltage_b,speed_a,speed_b\n0,5,5,0,0\n",
    "latin1.csv": "time_s,reference\n0,1\n1,caf\u00e9\n",
    "std.toml": _edit(GROUND, "nk = 2\n", "nk = 2\ntheta_std = ['a', 'b', 'c', 'd']\n"),
    # beside the model it was designed on, so that no warning says the model changed
    "controllers/est.toml": _edit(POLES, "[motors.a.estimator]\n", "estimator = 'kalman'\n[x]\n"),
    "controllers/timing.toml": _edit(
        POLES,
        "timing_noise_std_ticks = 0.5\n\n[motors.a.analysis]",
        "timing_noise_std_ticks = -0.5\n\n[motors.a.analysis]",
    ),
}

# fmt: off
CASES = [
    # a model file's [provenance] that is not a table: AttributeError
    ("inspect prov.toml", "prov.toml", "'provenance'", "wrong type"),
    ("design prov.toml --method pi", "prov.toml", "'provenance'"),
    ("inspect data.toml", "data.toml", "'data' in [provenance]", "wrong type"),  # was split
    # theta_std that is not numbers: ValueError from numpy
    ("export std.toml --mat x.mat", "std.toml", "theta_std in [motors.a]", "list of numbers"),
    # a controller's estimator that is not a table, or a timing noise out of range: tracebacks
    ("export controllers/est.toml --arduino", "est.toml", "[motors.a]", "estimator"),
    ("virtual-cart --onboard controllers/est.toml --duration 0.1", "est.toml", "estimator"),
    ("export controllers/timing.toml --arduino --out x.h", "timing.toml",
     "timing_noise_std_ticks must be a number of ticks in [0, 10], got -0.5"),
    ("virtual-cart --onboard controllers/timing.toml --duration 0.1", "timing_noise_std_ticks"),
    # a model no voltage moves: a numpy warning line, then 'it would need Kp = -inf'
    ("design zero.toml --method pi", "zero.toml: motor a's model has b = 0"),
    ("tune zero.toml --method pi", "zero.toml: motor a's model has b = 0"),
    # an on-board reference no motor reaches: 1e308 overflowed the cart's float channels (a
    # traceback in its thread, exit 0; monitor: 'no data from the cart', exit 1)
    ("virtual-cart --onboard controllers/pi.toml --reference const:1e308 --duration 0.1",
     "the reference asks for motor a 1e+308 rad/s"),
    ("monitor virtual --onboard controllers/pi.toml --reference const:1e39 --duration 0.1",
     "the reference asks for motor a 1e+39 rad/s"),
    # a gain or estimator matrix that is not numbers: numpy's words without the key
    ("run --fast --controller controllers/kp.toml", "kp.toml: [motors.a]: kp and ki must be numbers"),
    ("export controllers/K.toml --mat x.mat", "K (a list), Ki and Kr must be numbers"),
    ("export controllers/A.toml --arduino", "estimator.A must be numbers in rows of one length"),
    # a character device that is no terminal: 'cannot open ... Inappropriate ioctl', exit 1
    ("run --plant serial:/dev/null --rerun off", "serial port /dev/null is not a serial device"),
    ("monitor serial:/dev/null --duration 0.1", "serial port /dev/null is not a serial device"),
    # a newer version of a file: 'is neither a model file nor a controller file'
    ("export v9.toml --mat x.mat", "'cartctl-model/9', a version this cartctl does not read"),
    ("export controllers/v9.toml --mat x.mat", "'cartctl-controller/9', a version this"),
    # a trace of one row among several: the line did not say which file
    ("identify trace.csv one.csv", "one.csv has 1"),
    ("identify trace.csv --validate-on one.csv", "one.csv has 1"),
    ("validate models/ground.toml one.csv", "one.csv has 1"),
    # a reference file that is not UTF-8: UnicodeDecodeError
    ("run --fast --reference file:latin1.csv", "latin1.csv", "not UTF-8 text (byte 26)"),
    # a measurement noise that overflows: a trace of ±1e308, a traceback in the virtual cart's
    # thread (exit 0), a refusal of the trace being written (excite), or after the first stage
    ("run --fast --noise 1e308", "--noise", "up to 1000, got 1e+308"),
    ("virtual-cart --noise 1e308 --duration 0.1", "--noise", "up to 1000"),
    ("excite --signal step --amplitude 5 --noise 1e300 --out x.csv", "--noise", "up to 1000"),
    ("commission physics --noise 1e308", "--noise", "up to 1000"),
    # an output onto a file the command reads: the trace or model was replaced by the result
    ("identify trace.csv --out trace.csv", "--out trace.csv is a file this command reads"),
    ("identify trace.csv --compare models/air.toml --out ./models/air.toml", "--out"),
    ("design models/ground.toml --method pi --out models/ground.toml", "--out models/ground.toml"),
    ("tune models/ground.toml --method pi --choose 1 --out models/ground.toml", "--out"),
    ("export models/ground.toml --mat models/ground.toml", "--mat models/ground.toml"),
    # a file name longer than the file system takes: run started, made its folder, then failed
    # writing (exit 1); monitor connected first
    ("run --fast --out logs --name " + "x" * 300, "--out logs/xxx", "file name too long"),
    ("monitor virtual --duration 0.1 --out logs --name " + "x" * 300, "file name too long"),
    # ... into a folder that exists (Path.is_dir raised ENAMETOOLONG before that check)
    ("run --fast --out controllers --name " + "x" * 300, "--out controllers/xxx", "too long"),
    ("identify trace.csv --out " + "x" * 300 + ".toml", "--out xxx", "file name too long"),
    # estimator noise levels a controller file cannot hold: OverflowError, ValueError tracebacks
    ("design models/ground.toml --method poles --process-noise-v 1e308", "--process-noise-v",
     "up to 1000"),
    ("design models/ground.toml --method poles --bias-drift-v 1e200", "--bias-drift-v"),
    ("design models/ground.toml --method pi --estimator kalman --measurement-noise 1e200",
     "--measurement-noise"),
    ("tune models/ground.toml --method poles --process-noise-v 1e308", "--process-noise-v"),
    ("design models/ground.toml --method poles --measurement-noise 1000", "estimator.R",
     "--measurement-noise"),
    ("design models/ground.toml --method poles --bias-drift-v 1e-20", "does not decay",
     "--bias-drift-v"),
]
# fmt: on


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("bad_files")
    shutil.copytree(ROOT / "models", root / "models")
    (root / "controllers").mkdir()
    for name, text in FILES.items():
        (root / name).write_text(text, encoding="latin-1" if "latin" in name else "utf-8")
    return root


@pytest.mark.parametrize(("argv", "says"), [pytest.param(c[0], c[1:], id=c[0][:90]) for c in CASES])
def test_one_line_naming_the_mistake(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    folder: Path,
    argv: str,
    says: tuple[str, ...],
) -> None:
    monkeypatch.chdir(folder)
    before = {path: path.read_bytes() if path.is_file() else b"" for path in folder.rglob("*")}
    words = shlex.split(argv)
    code = main(words)
    out, err = capsys.readouterr()
    assert (code, out) == (2, ""), err
    (line,) = err.splitlines()
    assert line.startswith(f"cartctl {words[0]}: error: "), line
    assert all(text in line for text in says), line
    assert {
        path: path.read_bytes() if path.is_file() else b"" for path in folder.rglob("*")
    } == before


@pytest.mark.parametrize(
    ("name", "data"),
    [("bom.csv", b"\xef\xbb\xbftime_s,reference\n0,5\n1,8\n"),
     ("crlf.csv", b"time_s,reference\r\n0,5\r\n1,8\r\n")],
)  # fmt: skip
def test_a_reference_file_from_windows_runs(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, name: str, data: bytes
) -> None:
    """A UTF-8 BOM (the header's first name was '\\ufefftime_s') or CRLF line ends."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / name).write_bytes(data)
    argv = ["run", "--fast", "--rerun", "off", "--duration", "0.2", "--reference", f"file:{name}"]
    assert main(argv) == 0


@pytest.mark.parametrize(
    "argv", ["inspect models/ground.toml", "export controllers/pi.toml --arduino"]
)
def test_a_toml_file_saved_with_a_bom_reads(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, argv: str
) -> None:
    """A model or controller file saved by a Windows editor, with a UTF-8 BOM and CRLF line ends
    (the BOM was 'not a valid TOML model file (Invalid statement (at line 1, column 1))')."""
    monkeypatch.chdir(tmp_path)
    for folder in ("models", "controllers"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    path = tmp_path / shlex.split(argv)[1]
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes().replace(b"\n", b"\r\n"))
    assert main(shlex.split(argv)) == 0


def test_a_step_that_never_rises_is_shown(capsys: pytest.CaptureFixture[str]) -> None:
    """A pole a hair inside the unit circle: the simulated step never reaches 90 %, so it has no
    rise time (the table's formatting raised TypeError on None)."""
    assert main(["design", "models/ground.toml", "--method", "poles",
                 "--poles", "0.99999999999,0.5,0.5"]) == 0  # fmt: skip
    assert "rise —, settling —" in capsys.readouterr().out


def _square() -> Any:
    from cartctl.data.trace import Trace

    volts = [6.0 if k // 50 % 2 else -6.0 for k in range(400)]
    speed = [0.0, 0.0]
    for k in range(2, 400):  # a first-order motor with nk = 2, and a little noise
        speed.append(0.8 * speed[-1] + 0.5 * volts[k - 2] + 0.01 * ((k * 7919) % 13 - 6))
    return Trace.from_columns({"time_s": [k * 0.01 for k in range(400)], "voltage_a": volts,
                               "voltage_b": volts, "speed_a": speed, "speed_b": speed})  # fmt: skip


@pytest.mark.parametrize(
    ("call", "says"),
    [(lambda: cartctl.excite(plant="sim", signal="step", amplitude_v=10**400), "amplitude_v"),
     (lambda: cartctl.excite(plant="sim", signal="step", noise_std_rad_s=10**400), "--noise"),
     (lambda: cartctl.simulate("controllers/pi.toml", noise_std_rad_s=10**400), "--noise"),
     (lambda: cartctl.identify(_square(), prefilter_hz=10**400), "--cutoff-hz")],
)  # fmt: skip
def test_the_api_refuses_a_whole_number_beyond_any_float(call: Any, says: str) -> None:
    """A Python int too large for a float raised OverflowError from math.isnan."""
    with pytest.raises(InputError, match=says):
        call()


def test_a_cut_recording_is_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """A recording cut mid-message or to its first bytes: the Rerun SDK's warning (no footer, a
    legacy format) came as a line of its own before the refusal."""
    argv = ["run", "--fast", "--rerun", "save", "--duration", "0.3", "--out", str(tmp_path)]
    assert main([*argv, "--name", "r"]) == 0
    data = (tmp_path / "r.rrd").read_bytes()
    for name, cut in (("half.rrd", data[: len(data) // 2]), ("head.rrd", data[:20])):
        (tmp_path / name).write_bytes(cut)
        capsys.readouterr()
        assert main(["review", str(tmp_path / name)]) == 2
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith("cartctl review: error: ") and name in line, line


def test_a_numpy_cut_off_is_taken() -> None:
    """The overflow guard of the prefilter's cut-off leaves numpy numbers alone (16954d6 raised
    OverflowError for np.float64(5.0): numpy compared it with 2**1024)."""
    import numpy as np

    for cutoff in (np.float64(5.0), np.float32(5.0), np.int64(5)):
        assert set(cartctl.identify(_square(), prefilter_hz=cutoff).motors) == {"a", "b"}
