"""Every command's ``--json`` output is strict JSON: no ``NaN``, ``Infinity`` or ``-Infinity``.

Each document is parsed with a parser that rejects those constants, as JavaScript's ``JSON.parse``,
Go and serde do. The data are real: excitation and steps of the physics simulator, the shipped
models and controllers, a QRC sample.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.cli.jsonout import dumps, strict
from cartctl.data.read import read_trace

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"


def _reject(constant: str) -> Any:
    raise ValueError(f"not JSON: {constant}")


def strict_loads(text: str) -> Any:
    return json.loads(text, parse_constant=_reject)


def _json(capsys: pytest.CaptureFixture[str], *argv: str) -> Any:
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert code == 0, err
    return strict_loads(out)


def test_the_strict_parser_rejects_what_python_writes_by_default() -> None:
    loose = json.dumps({"fit": -math.inf, "x": [math.nan, 1.0]})
    with pytest.raises(ValueError, match="not JSON"):
        strict_loads(loose)


def test_dumps_turns_non_finite_numbers_and_numpy_types_into_json() -> None:
    value = {
        "fit": -math.inf,
        "nan": float("nan"),
        "np": np.float64("inf"),
        "arr": np.array([1.0, np.nan]),
        "int": np.int64(3),
        "flag": np.bool_(True),
        "tuple": (1, -9.9e117),
    }
    doc = strict_loads(dumps(value))
    assert doc == {
        "fit": None, "nan": None, "np": None, "arr": [1.0, None], "int": 3, "flag": True,
        "tuple": [1, -9.9e117],
    }  # fmt: skip
    assert strict(1.5) == 1.5 and strict("a") == "a" and strict(None) is None


@pytest.fixture
def square_csv(capsys: pytest.CaptureFixture[str], workdir: Path) -> Path:
    code = main(["excite", "--plant", "physics", "--signal", "square", "--amplitude", "6",
                 "--cycles", "2", "--out", "sq.csv"])  # fmt: skip
    capsys.readouterr()
    assert code == 0
    return workdir / "sq.csv"


def test_every_json_command_prints_strict_json(
    capsys: pytest.CaptureFixture[str], workdir: Path, square_csv: Path
) -> None:
    ident = _json(capsys, "identify", str(square_csv), "--delay", "auto", "--json")
    assert set(ident["motors"]) == {"a", "b"}
    for motor in ident["motors"].values():  # candidates that fit badly stay numbers or null
        for candidate in motor["delay_estimate"]["candidates"]:
            assert all(v is None or isinstance(v, int | float) for v in candidate.values())
    _json(capsys, "inspect", "models/ground.toml", "--json")
    _json(capsys, "design", "models/ground.toml", "--method", "pi", "--json")
    _json(capsys, "design", "models/ground.toml", "--method", "poles", "--json")
    run = _json(capsys, "run", "--fast", "--duration", "0.5", "--rerun", "off", "--json",
                "--name", "j")  # fmt: skip
    _json(capsys, "review", run["trace"], "--json")
    _json(capsys, "validate", "models/ground.toml", str(square_csv), "--json")
    _json(capsys, "tune", "models/ground.toml", "--method", "pi", "--jobs", "1", "--grid",
          "phase_margin=60:65:5,crossover_hz=3:4:1", "--duration", "0.5", "--json")  # fmt: skip
    _json(capsys, "convert", str(DATA / "qrc6_sample.csv"), "--map",
          "voltage_a=voltA,speed_a=speedA", "--out", "q.csv", "--json")  # fmt: skip
    excited = _json(capsys, "excite", "--plant", "physics", "--signal", "prbs", "--amplitude",
                    "5", "--duration", "1", "--motor", "a", "--out", "p.csv", "--json")  # fmt: skip
    trace = read_trace(workdir / "p.csv")
    assert excited["ticks"] == len(trace) == 100 and excited["duration_s"] == pytest.approx(1.0)
    assert excited["loop_delay_ticks"] == 1 and excited["stopped"] is None  # physics: on board
    assert excited["trace"] == "p.csv" and not trace.voltage_b.any()  # motor a only


def test_linearity_json_is_strict(capsys: pytest.CaptureFixture[str], workdir: Path) -> None:
    files = []
    for volts in (4, 6, 10):
        name = f"step{volts}.csv"
        code = main(["excite", "--plant", "physics", "--signal", "step", "--amplitude",
                     str(volts), "--duration", "1", "--motor", "a", "--out", name])  # fmt: skip
        assert code == 0
        files.append(name)
    capsys.readouterr()
    doc = _json(capsys, "linearity", *files, "--json")
    assert doc["motor"] == "a"
