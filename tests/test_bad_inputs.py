"""A table of user mistakes across every command: each one gives exactly one line on stderr,
``cartctl COMMAND: error: …``, that names the option or file given and the real mistake; exit 2,
nothing on stdout, no traceback, and nothing driven or written (each refuses before the work).

The cases run in-process (``cartctl.cli.main``) in one folder holding the shipped models and
controllers, a valid trace and the wrong things a user may give: a directory, an empty file, a
text file, a file that is not TOML, a controller file for another period.
"""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cartctl.cli import main

ROOT = Path(__file__).resolve().parents[1]

NAN = "must be a number, got nan"
DIR = "is a directory"
MISSING = "not found"
EMPTY = "the file is empty"


def _case(argv: str, *says: str) -> Any:
    """A row: the command line (shell words) and what its one error line must contain."""
    return pytest.param(shlex.split(argv), says, id=argv)


# fmt: off
CASES = [
    # excite
    _case("excite --plant moon --signal step --amplitude 5 --out x.csv", "unknown plant 'moon'"),
    _case("excite --signal step --amplitude nan --out x.csv", "--amplitude", NAN),
    _case("excite --signal step --amplitude inf --out x.csv", "--amplitude", "must be finite"),
    _case("excite --signal step --amplitude 20 --out x.csv", "--amplitude", "12 V"),
    _case("excite --signal step --amplitude -3 --out x.csv", "--amplitude", "positive"),
    _case("excite --signal step --amplitude 5 --noise -1 --out x.csv", "--noise", ">= 0"),
    _case("excite --signal step --amplitude 5 --noise nan --out x.csv", "--noise", NAN),
    _case("excite --signal step --amplitude 5 --duration -1 --out x.csv", "--duration"),
    _case("excite --signal step --amplitude 5 --duration nan --out x.csv", "--duration"),
    _case("excite --signal square --amplitude 5 --cycles 0 --out x.csv", "--cycles", "at least 1"),
    _case("excite --signal prbs --amplitude 5 --cycles 2 --out x.csv", "--cycles", "prbs signal"),
    _case("excite --signal multisine --amplitude 5 --cycles 2 --duration 3 --out x.csv",
          "--cycles and --duration", "give one"),
    _case("excite --signal step --amplitude 5 --out folder", "--out folder", "is a folder"),
    _case("excite --signal step --amplitude 5 --out file.txt/x.csv", "--out", "file.txt is a file"),
    _case("excite --model missing.toml --signal step --amplitude 5 --out x.csv", "missing.toml",
          MISSING),
    _case("excite --model trace.csv --signal step --amplitude 5 --out x.csv", "trace.csv",
          "is a CSV file, not a model file"),
    _case("excite --model controllers/pi.toml --signal step --amplitude 5 --out x.csv",
          "controllers/pi.toml", "is a controller file, not a model file"),
    _case("excite --model empty.toml --signal step --amplitude 5 --out x.csv", "empty.toml", EMPTY),
    _case("excite --model folder.toml --signal step --amplitude 5 --out x.csv", "folder.toml", DIR),
    _case("excite --plant physics --connect-timeout -1 --signal step --amplitude 5 --out x.csv",
          "--connect-timeout", "positive"),
    _case("excite --plant virtual --connect-timeout nan --signal step --amplitude 5 --out x.csv",
          "--connect-timeout", NAN),
    # identify
    _case("identify missing.csv", "missing.csv", MISSING),
    _case("identify folder.csv", "folder.csv", DIR),
    _case("identify empty.csv", "empty.csv", EMPTY),
    _case("identify models/ground.toml", "models/ground.toml", "is a model file, not a trace"),
    _case("identify trace.csv --report file.txt", "--report file.txt", "is a file, not a folder"),
    _case("identify trace.csv --cutoff-hz 5 --zero-phase", "--cutoff-hz and --zero-phase",
          "need --prefilter butter"),
    _case("identify trace.csv --out folder", "--out folder", "is a folder, not a file"),
    _case("identify trace.csv --out file.txt/m.toml", "--out", "file.txt is a file"),
    _case("identify trace.csv --prefilter butter --order 0", "--order", "1..12"),
    _case("identify trace.csv --prefilter butter --cutoff-hz nan", "--cutoff-hz", NAN),
    _case("identify trace.csv --prefilter butter --cutoff-hz -1", "--cutoff-hz", "positive"),
    _case("identify trace.csv --prefilter butter --cutoff-hz 80", "--cutoff-hz", "Nyquist"),
    _case("identify trace.csv --delay -1", "--delay", "0..50"),
    _case("identify trace.csv --delay soon", "--delay", "'soon'"),
    _case("identify trace.csv --nb 0", "--nb", "1..50"),
    _case("identify trace.csv --loop-delay -1", "--loop-delay"),
    _case("identify trace.csv --compare missing.toml", "missing.toml", MISSING),
    _case("identify trace.csv --compare trace.csv", "trace.csv", "is a CSV file"),
    _case("identify trace.csv --validate-on missing.csv", "missing.csv", MISSING),
    _case("identify trace.csv --validate-on folder", "folder", DIR),
    _case("identify trace.csv --split nan", "--split"),
    _case("identify trace.csv --split 1.5", "--split"),
    _case("identify trace.csv --map nonsense", "--map", "'nonsense'"),
    _case("identify binary.toml", "binary.toml", "binary"),
    # inspect
    _case("inspect missing.toml", "missing.toml", MISSING),
    _case("inspect folder.toml", "folder.toml", DIR),
    _case("inspect empty.toml", "empty.toml", EMPTY),
    _case("inspect trace.csv", "trace.csv", "is a CSV file, not a model file"),
    _case("inspect controllers/pi.toml", "controllers/pi.toml", "is a controller file"),
    _case("inspect garbage.toml", "garbage.toml", "not a valid TOML model file"),
    _case("inspect binary.toml", "binary.toml", "is not text"),
    _case("inspect nan.toml", "nan.toml", "theta", "finite"),
    # validate
    _case("validate missing.toml trace.csv", "missing.toml", MISSING),
    _case("validate models/ground.toml missing.csv", "missing.csv", MISSING),
    _case("validate trace.csv models/ground.toml", "trace.csv", "is a CSV file"),
    _case("validate models/ground.toml folder", "folder", DIR),
    _case("validate models/ground.toml empty.csv", "empty.csv", EMPTY),
    _case("validate models/ground.toml controllers/pi.toml", "controllers/pi.toml",
          "is a controller file, not a trace"),
    _case("validate models/ground.toml trace.csv --plot folder", "--plot", "'folder'"),
    _case("validate controllers/pi.toml trace.csv", "controllers/pi.toml", "is a controller file"),
    # linearity
    _case("linearity trace.csv trace.csv missing.csv", "missing.csv", MISSING),
    _case("linearity trace.csv folder trace.csv", "folder", DIR),
    _case("linearity empty.csv trace.csv trace.csv", "empty.csv", EMPTY),
    _case("linearity models/ground.toml trace.csv trace.csv", "models/ground.toml",
          "is a model file, not a trace"),
    # design
    _case("design missing.toml --method pi", "missing.toml", MISSING),
    _case("design folder.toml --method pi", "folder.toml", DIR),
    _case("design trace.csv --method pi", "trace.csv", "is a CSV file, not a model file"),
    _case("design controllers/pi.toml --method pi", "controllers/pi.toml", "is a controller file"),
    _case("design empty.toml --method pi", "empty.toml", EMPTY),
    _case("design nan.toml --method pi", "nan.toml", "theta", "finite"),
    _case("design models/ground.toml --method poles --poles 0.5", "--poles", "needs 3"),
    _case("design models/ground.toml --method pi --phase-margin nan", "--phase-margin", NAN),
    _case("design models/ground.toml --method pi --phase-margin 120", "--phase-margin", "89"),
    _case("design models/ground.toml --method pi --phase-margin -10", "--phase-margin", "89"),
    _case("design models/ground.toml --method pi --crossover-hz nan", "--crossover-hz", NAN),
    _case("design models/ground.toml --method pi --crossover-hz -1", "--crossover-hz", "Nyquist"),
    _case("design models/ground.toml --method pi --crossover-hz 60", "--crossover-hz", "Nyquist"),
    _case("design models/ground.toml --method pi --bandwidth-hz inf", "--bandwidth-hz", "finite"),
    _case("design models/ground.toml --method poles --measurement-noise -1",
          "--measurement-noise", ">= 0"),
    _case("design models/ground.toml --method poles --measurement-noise nan",
          "--measurement-noise", NAN),
    _case("design models/ground.toml --method poles --process-noise-v -1", "--process-noise-v"),
    _case("design models/ground.toml --method poles --bias-drift-v nan", "--bias-drift-v", NAN),
    _case("design models/ground.toml --method pi --process-noise-v 0.2 --measurement-noise 1",
          "--process-noise-v and --measurement-noise are for an estimator", "--estimator kalman"),
    _case("design models/ground.toml --method pi --poles 0.5,0.5,0.5", "--poles is for --method poles"),
    _case("design models/ground.toml --method poles --phase-margin 40 --anti-windup none",
          "--phase-margin and --anti-windup are for --method pi"),
    # given at their defaults (0.1 V, 65°): refused all the same
    _case("design models/ground.toml --method pi --process-noise-v 0.1",
          "--process-noise-v is for an estimator"),
    _case("design models/ground.toml --method poles --phase-margin 65",
          "--phase-margin is for --method pi"),
    # pole placement always runs on its Kalman estimate: --estimator none was ignored
    _case("design models/ground.toml --method poles --estimator none",
          "--estimator is for --method pi"),
    _case("design models/ground.toml --method pi --bandwidth-hz 5 --crossover-hz 2",
          "--crossover-hz is for a PI without --bandwidth-hz"),
    _case("design models/ground.toml --method poles --poles 0.5,0.5,0.5 --overshoot 2",
          "--overshoot is for placing poles from a specification, not with --poles"),
    _case("design models/ground.toml --method pi --voltage-limit nan", "--voltage-limit", NAN),
    _case("design models/ground.toml --method pi --voltage-limit 20", "--voltage-limit", "12"),
    _case("design models/ground.toml --method poles --settling-time -1", "--settling-time"),
    _case("design models/ground.toml --method poles --settling-time nan", "--settling-time", NAN),
    _case("design models/ground.toml --method poles --overshoot -1", "--overshoot", "100"),
    _case("design models/ground.toml --method poles --overshoot nan", "--overshoot", NAN),
    _case("design models/ground.toml --method poles --poles fast", "--poles", "'fast'"),
    _case("design models/ground.toml --method poles --poles 1.5,0.5,0.5", "--poles",
          "unit circle"),
    _case("design models/ground.toml --method poles --poles nan,0.5,0.5", "--poles", "finite"),
    _case("design models/ground.toml --method poles --poles ''", "--poles must be text like",
          "got ''"),  # (it designed from the settling time and overshoot)
    _case("design models/ground.toml --method poles --poles infj,0.5,0.5", "--poles", "infj",
          "finite"),  # (it was placed at 0)
    _case("design models/ground.toml --method poles --poles 0.5+1e999j,0.5-1e999j,0.5",
          "--poles", "finite"),
    _case("design models/ground.toml --method pi --out folder", "--out folder", "is a folder"),
    _case("design models/ground.toml --method pi --report file.txt", "--report file.txt",
          "is a file, not a folder"),
    _case("design models/ground.toml --method pi --extra-delay -1", "--extra-delay"),
    _case("design models/ground.toml --method pi --loop-delay -1", "--loop-delay"),
    _case("design models/ground.toml --method poles --timing-noise-ticks nan",
          "--timing-noise-ticks", NAN),
    _case("design models/ground.toml --method pi --disturbance-v nan", "--disturbance-v", NAN),
    _case("design models/ground.toml --method pi --step 0", "--step", "non-zero"),
    _case("design models/ground.toml --method pi --step inf", "--step", "finite"),
    # run (each refuses before a plant is made: no real-time run)
    _case("run --plant moon --rerun off", "unknown plant 'moon'"),
    _case("run --fast --plant moon", "unknown plant 'moon'"),
    _case("run --fast --plant virtual", "--fast needs a simulated plant"),
    # a plant option the plant does not use: it was silently ignored
    _case("run --fast --plant physics --model models/air.toml", "--model is for the sim plant"),
    _case("run --fast --connect-timeout 3", "--connect-timeout is for the virtual and serial plants"),
    _case("excite --plant sim --preset air --signal step --amplitude 5 --out x.csv",
          "--preset is for the physics and virtual plants", "--plant sim does not use it"),
    _case("run --fast --controller missing.toml", "missing.toml", MISSING),
    _case("run --fast --controller folder.toml", "folder.toml", DIR),
    _case("run --fast --controller trace.csv", "trace.csv", "is a CSV file, not a controller"),
    _case("run --fast --controller models/ground.toml", "models/ground.toml",
          "is a model file, not a controller file"),
    _case("run --fast --controller empty.toml", "empty.toml", EMPTY),
    _case("run --fast --controller garbage.toml", "garbage.toml", "not a valid TOML"),
    _case("run --fast --controller pi20.toml", "pi20.toml", "Ts = 0.02 s", "ticks every 0.01 s"),
    _case("run --fast --model missing.toml", "missing.toml", MISSING),
    _case("run --fast --model controllers/pi.toml", "controllers/pi.toml", "is a controller file"),
    _case("run --fast --duration nan", "--duration"),
    _case("run --fast --duration -1", "--duration"),
    _case("run --fast --reference fast", "--reference", "'fast'"),
    _case("run --fast --reference-b step:x", "--reference-b", "step:x"),
    _case("run --fast --reference file:missing.csv", "missing.csv", MISSING),
    _case("run --fast --voltage-limit nan", "--voltage-limit", NAN),
    _case("run --fast --voltage-limit 20", "--voltage-limit", "12"),
    _case("run --fast --noise -1", "--noise", ">= 0"),
    _case("run --fast --noise nan", "--noise", NAN),
    _case("run --fast --out file.txt", "--out file.txt", "is a file, not a folder"),
    _case("run --plant virtual --connect-timeout -1 --rerun off", "--connect-timeout"),
    _case("run --plant physics:actuation_ms=99 --fast", "actuation_ms"),
    _case("run --plant physics:actuation_ms=nan --fast", "actuation_ms", "must be a number"),
    _case("run --plant serial: --rerun off", "needs a port"),
    _case("run --fast --seed -1", "--seed", ">= 0"),
    _case("run --fast --model nan.toml", "nan.toml", "finite"),
    _case("run --fast --reference file:folder", "folder", DIR),
    # review
    _case("review missing.rrd", "missing.rrd", MISSING),
    _case("review folder.rrd", "folder.rrd", DIR),
    _case("review empty.rrd", "empty.rrd", EMPTY),
    _case("review models/ground.toml", "models/ground.toml", ".rrd"),
    _case("review empty.csv", "empty.csv", EMPTY),
    _case("review folder.csv", "folder.csv", DIR),
    _case("review garbage.rrd", "garbage.rrd", "not a readable Rerun recording"),
    _case("review trace.csv --compare missing.csv", "--compare missing.csv", MISSING),
    _case("review trace.csv --model missing.toml", "--model missing.toml", MISSING),
    _case("review trace.csv --model folder.toml", "--model folder.toml", DIR),
    # tune (its grid's checks: test_tune_*)
    _case("tune missing.toml --method pi", "missing.toml", MISSING),
    _case("tune trace.csv --method pi", "trace.csv", "is a CSV file"),
    _case("tune controllers/pi.toml --method pi", "controllers/pi.toml", "is a controller file"),
    _case("tune models/ground.toml --method pi --plant moon", "--plant", "'moon'"),
    _case("tune models/ground.toml --method pi --jobs 0", "--jobs"),
    _case("tune models/ground.toml --method pi --duration nan", "--duration"),
    _case("tune models/ground.toml --method pi --extra-delay -1", "--extra-delay"),
    _case("tune models/ground.toml --method pi --robust --plants 0", "--plants"),
    _case("tune models/ground.toml --method pi --robust --actuation-ms nan", "--actuation-ms",
          "must be a number"),
    _case("tune models/ground.toml --method pi --choose 1 --out folder", "--out folder"),
    _case("tune models/ground.toml --method pi --plot folder", "--plot folder"),
    _case("tune models/ground.toml --method pi --plot x.txt", "--plot", ".png"),
    _case("tune models/ground.toml --method pi --robust --seed -3", "--seed"),
    _case("tune models/ground.toml --method poles --process-noise-v -1", "--process-noise-v"),
    _case("tune models/ground.toml --method pi --bias-drift-v 0.1",
          "--bias-drift-v only applies to --method poles"),
    _case("tune models/ground.toml --method pi --process-noise-v 0.1 --bias-drift-v 0.1",
          "--process-noise-v and --bias-drift-v only apply to --method poles"),
    # convert
    _case("convert missing.csv", "missing.csv", MISSING),
    _case("convert folder.csv", "folder.csv", DIR),
    _case("convert empty.csv", "empty.csv", EMPTY),
    _case("convert models/ground.toml", "models/ground.toml", "is a model file, not a trace"),
    _case("convert trace.csv --out folder", "--out folder", "is a folder, not a file"),
    _case("convert trace.csv --map speed_a", "--map", "'speed_a'"),
    # export
    _case("export missing.toml --arduino", "missing.toml", MISSING),
    _case("export folder.toml --arduino", "folder.toml", DIR),
    _case("export trace.csv --arduino", "trace.csv", "is a CSV file"),
    _case("export empty.toml --mat x.mat", "empty.toml", EMPTY),
    _case("export garbage.toml --mat x.mat", "garbage.toml", "not a valid TOML"),
    _case("export models/ground.toml --arduino", "--arduino needs a controller file",
          "models/ground.toml is a model file"),
    _case("export controllers/pi.toml --arduino --out folder", "--out folder", "is a folder"),
    _case("export controllers/pi.toml --mat folder", "--mat folder", "is a folder"),
    # virtual-cart (each refuses before its pseudo-terminal opens)
    _case("virtual-cart --noise -1 --duration 0.1", "--noise", ">= 0"),
    _case("virtual-cart --noise nan --duration 0.1", "--noise", NAN),
    _case("virtual-cart --faults moon=1 --duration 0.1", "--faults", "'moon=1'"),
    # the bridge sketch's version with an on-board controller: it was silently ignored
    _case("virtual-cart --onboard controllers/pi.toml --faults bridge=1 --duration 0.1",
          "bridge=1 sets up the bridge sketch", "on-board controller"),
    _case("monitor virtual:bridge=1 --onboard controllers/pi.toml --duration 0.1",
          "bridge=1 sets up the bridge sketch", "on-board controller"),
    _case("virtual-cart --duration nan", "--duration"),
    _case("virtual-cart --seed x --duration 0.1", "--seed"),
    _case("virtual-cart --onboard missing.toml --duration 0.1", "missing.toml", MISSING),
    _case("virtual-cart --onboard models/ground.toml --duration 0.1", "models/ground.toml",
          "is a model file, not a controller file"),
    _case("virtual-cart --onboard controllers/pi.toml --reference fast --duration 0.1",
          "--reference", "'fast'"),
    # monitor (each refuses before a cart is made)
    _case("monitor moon --duration 0.1", "unknown plant 'moon'"),
    _case("monitor moon --duration nan", "unknown plant 'moon'"),
    _case("monitor serial: --duration 0.1", "needs a port"),
    _case("monitor virtual --duration nan", "--duration"),
    _case("monitor virtual --duration 0.1 --out file.txt", "--out file.txt", "is a file"),
    # --connect-url without --rerun connect: it was silently ignored
    _case("monitor virtual --duration 0.1 --connect-url rerun+http://127.0.0.1:9/proxy",
          "--connect-url is for --rerun connect", "not --rerun auto"),
    _case("run --fast --rerun save --connect-url rerun+http://127.0.0.1:9/proxy",
          "--connect-url is for --rerun connect", "not --rerun save"),
    _case("monitor virtual --duration 0.1 --onboard missing.toml", "missing.toml", MISSING),
    _case("monitor virtual --duration 0.1 --onboard controllers/pi.toml --reference x",
          "--reference", "'x'"),
    _case("monitor virtual --duration 0.1 --labels nonsense", "--labels", "'nonsense'"),
    _case("monitor serial:folder --duration 0.1", "serial port folder is a folder"),
    _case("run --plant serial:trace.csv --rerun off", "serial port trace.csv is not a serial device"),
    _case("monitor virtual --duration 0.1 --connect-timeout nan", "--connect-timeout"),
    # commission (each refuses before a cart is made)
    _case("commission moon", "PLANT", "'moon'"),
    _case("commission physics --out file.txt", "--out file.txt", "is a file"),
    _case("commission physics --jobs 0", "--jobs"),
    _case("commission physics --noise -1", "--noise"),
    _case("commission physics --seed -1", "--seed"),
    _case("commission serial:", "needs a port"),
    _case("commission serial:/dev/ttyNOPE", "serial port /dev/ttyNOPE does not exist"),
    _case("commission serial:folder", "serial port folder is a folder, not a serial device"),
    _case("commission serial:/dev/null", "serial port /dev/null is not a serial device"),
    _case("commission virtual --connect-timeout nan", "--connect-timeout"),
    # a plant option the plant does not use: it was silently ignored
    _case("commission physics --connect-timeout 3",
          "--connect-timeout is for the virtual and serial plants", "PLANT physics does not use it"),
    _case("commission serial:/dev/ttyACM0 --preset air", "--preset is for the physics and virtual"),
    _case("commission serial:/dev/ttyACM0 --noise 0.2", "--noise is for the sim, physics and"),
]
# fmt: on


def _make_folder(root: Path) -> None:
    """The shipped models and controllers, a valid trace, and the wrong things to give."""
    from cartctl.data.trace import Trace, write_trace

    shutil.copytree(ROOT / "models", root / "models")
    shutil.copytree(ROOT / "controllers", root / "controllers")
    n = 600
    volts = np.where((np.arange(n) // 50) % 2 == 0, 6.0, -6.0)
    speed = np.convolve(volts, np.full(5, 0.4), mode="same")
    columns = {"time_s": np.arange(n) * 0.01, "voltage_a": volts, "voltage_b": volts,
               "speed_a": speed, "speed_b": speed}  # fmt: skip
    write_trace(Trace.from_columns(columns), root / "trace.csv")
    for name in ("empty.csv", "empty.toml", "empty.rrd"):
        (root / name).write_bytes(b"")
    for name in ("folder", "folder.csv", "folder.toml", "folder.rrd"):
        (root / name).mkdir()
    (root / "file.txt").write_text("hello\n", encoding="utf-8")
    (root / "garbage.toml").write_text("this is = not [toml\n", encoding="utf-8")
    (root / "garbage.rrd").write_text("not a recording\n", encoding="utf-8")
    (root / "binary.toml").write_bytes(bytes(range(256)))
    ground = (root / "models" / "ground.toml").read_text(encoding="utf-8")
    theta = "\ntheta = [-0.9356,"
    assert theta in ground
    (root / "nan.toml").write_text(ground.replace(theta, "\ntheta = [nan,", 1), encoding="utf-8")
    pi = (root / "controllers" / "pi.toml").read_text(encoding="utf-8")
    assert "\nperiod_s = 0.01\n" in pi
    (root / "pi20.toml").write_text(pi.replace("\nperiod_s = 0.01\n", "\nperiod_s = 0.02\n"),
                                    encoding="utf-8")  # fmt: skip


def _listing(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.fixture(scope="module")
def mistakes_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("mistakes")
    _make_folder(root)
    return root


def _run(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own refusals
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(("argv", "says"), CASES)
def test_a_mistake_is_one_line_naming_it(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    mistakes_folder: Path,
    argv: list[str],
    says: tuple[str, ...],
) -> None:
    monkeypatch.chdir(mistakes_folder)
    before = _listing(mistakes_folder)
    code, out, err = _run(capsys, argv)
    lines = err.splitlines()
    assert code == 2, err
    assert out == ""
    assert len(lines) == 1, err
    assert lines[0].startswith(f"cartctl {argv[0]}: error: "), lines[0]
    for text in says:
        assert text in lines[0], lines[0]
    assert "Traceback" not in err
    assert _listing(mistakes_folder) == before  # refused before anything was written


def test_the_table_covers_every_command() -> None:
    from cartctl.cli import build_parser

    commands = set(build_parser().subcommands) - {"--help"}
    covered = {case.values[0][0] for case in CASES}
    assert commands <= covered, commands - covered
    assert len(CASES) >= 100


def test_a_field_name_or_class_never_shows(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, mistakes_folder: Path
) -> None:
    """The measured cases that named internals (a request field, a dataclass) now name options."""
    from cartctl.design.request import OPTIONS

    monkeypatch.chdir(mistakes_folder)
    internals = [*OPTIONS, "CartParams", "noise_std_rad_s", "Reader needs"]
    for argv in (
        "design models/ground.toml --method poles --measurement-noise -1",
        "excite --signal step --amplitude 5 --noise -1 --out x.csv",
        "virtual-cart --noise -1 --duration 0.1",
        "excite --signal step --amplitude nan --out x.csv",
        "export controllers/pi.toml --mat folder",
    ):
        code, _, err = _run(capsys, shlex.split(argv))
        assert code == 2
        assert not [name for name in internals if name in err], err
        assert "beyond" not in err  # nan is not a number, not a value out of range


def test_the_plant_name_is_checked_before_what_depends_on_it(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, mistakes_folder: Path
) -> None:
    monkeypatch.chdir(mistakes_folder)
    for argv in (["run", "--fast", "--plant", "moon"],
                 ["run", "--fast", "--plant", "moon", "--controller", "pi20.toml"]):  # fmt: skip
        code, _, err = _run(capsys, argv)
        assert code == 2 and "unknown plant 'moon'" in err and "--fast" not in err


def test_the_period_is_checked_before_the_coefficients(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, mistakes_folder: Path
) -> None:
    """pi20.toml's coefficients were computed for Ts = 10 ms: with its period set to 20 ms they
    disagree with its gains too, but the period is the mistake (a file for another plant)."""
    from cartctl.design.controllerfile import load_controller

    monkeypatch.chdir(mistakes_folder)
    with pytest.raises(ValueError, match="controller_num"):  # the coefficients do disagree
        load_controller("pi20.toml")
    code, _, err = _run(capsys, ["run", "--fast", "--controller", "pi20.toml"])
    assert code == 2 and "Ts = 0.02 s" in err and "controller_num" not in err


def test_a_folder_given_as_a_recording_or_file_says_so(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, mistakes_folder: Path
) -> None:
    monkeypatch.chdir(mistakes_folder)
    for argv in (["review", "folder.rrd"], ["inspect", "folder.toml"],
                 ["run", "--fast", "--controller", "folder.toml"]):  # fmt: skip
        code, _, err = _run(capsys, argv)
        assert code == 2 and DIR in err and MISSING not in err, err
    code, _, err = _run(capsys, ["identify", "trace.csv", "--report", "file.txt"])
    assert code == 2 and "--report file.txt" in err and "File exists" not in err


@pytest.mark.filterwarnings("always::cartctl.errors.DataWarning")  # the CLI prints it
def test_a_warning_names_its_command(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A controller whose model changed since its design runs with one warning line that starts
    with ``cartctl run: warning:``."""
    monkeypatch.chdir(tmp_path)
    shutil.copytree(ROOT / "models", tmp_path / "models")
    assert main(["design", "models/ground.toml", "--method", "pi", "--out", "c.toml"]) == 0
    model = tmp_path / "models" / "ground.toml"
    model.write_text(model.read_text(encoding="utf-8") + "\n# edited\n", encoding="utf-8")
    capsys.readouterr()
    code = main(["run", "--fast", "--controller", "c.toml", "--rerun", "off", "--duration", "0.5",
                 "--out", "logs"])  # fmt: skip
    err = capsys.readouterr().err
    warnings_seen = [line for line in err.splitlines() if "warning:" in line]
    assert code == 0
    assert warnings_seen, err
    assert all(line.startswith("cartctl run: warning: ") for line in warnings_seen), err
    assert any("which has changed" in line for line in warnings_seen)


def test_every_warning_print_names_its_command() -> None:
    """No module prints a bare ``warning:`` or ``cartctl: warning:`` line."""
    source = ROOT / "src" / "cartctl"
    bad = []
    for path in source.rglob("*.py"):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if ('"warning: ' in line or "cartctl: warning" in line) and "print" in line:
                bad.append(f"{path.relative_to(source)}:{number}")
    assert not bad, bad
