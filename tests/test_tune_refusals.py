"""``cartctl tune`` refuses what ``cartctl design`` refuses, in design's words, before any work.

A grid value out of the range of its design option, a malformed grid and an unusable model give
one line and exit 2 without designing or running anything; a setting that only its own design
refuses (a crossover no PI reaches on this model) stays a row of the table.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.cli import main
from cartctl.design.request import DesignRequest
from cartctl.errors import InputError
from cartctl.tune import engine
from cartctl.tune.grid import AXES, FIELDS, parse_grid

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"


class WorkStartedError(Exception):
    """Raised by the patched expensive steps: a refusal must come before them."""


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Designing a setting or running the grid fails the test."""

    def refuse(*_args: object, **_kwargs: object) -> None:
        raise WorkStartedError("the grid started before the refusal")

    monkeypatch.setattr(engine, "run_grid", refuse)
    monkeypatch.setattr(engine, "design_motor", refuse)


def _cli(*argv: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's own usage errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def _one_line(command: str, err: str) -> str:
    """The message of a one-line refusal (without the 'cartctl COMMAND: error: ' prefix)."""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    prefix = f"cartctl {command}: error: "
    assert lines[0].startswith(prefix), err
    return lines[0][len(prefix) :]


# (method, grid item, the design option of that axis and the value design is given)
OUT_OF_RANGE = [
    ("pi", "phase_margin=120", "--phase-margin", "120"),
    ("pi", "phase-margin=120", "--phase-margin", "120"),
    ("pi", "crossover-hz=60", "--crossover-hz", "60"),
    ("poles", "settling-time=-0.1", "--settling-time", "-0.1"),
    ("pi", "phase_margin=0", "--phase-margin", "0"),
    ("pi", "phase_margin=-5", "--phase-margin", "-5"),
    ("pi", "crossover_hz=60", "--crossover-hz", "60"),
    ("pi", "crossover_hz=0", "--crossover-hz", "0"),
    ("poles", "overshoot=150", "--overshoot", "150"),
    ("poles", "overshoot=0", "--overshoot", "0"),
    ("poles", "settling_time=-0.1", "--settling-time", "-0.1"),
]


@pytest.mark.parametrize(("method", "item", "option", "value"), OUT_OF_RANGE)
def test_an_out_of_range_grid_value_gets_designs_line(
    capsys: pytest.CaptureFixture[str], no_work: None, method: str, item: str, option: str,
    value: str,
) -> None:  # fmt: skip
    code, out, err = _cli("design", str(GROUND), "--method", method, f"{option}={value}",
                          capsys=capsys)  # fmt: skip
    assert code == 2 and out == ""
    design_says = _one_line("design", err)
    assert design_says.startswith(f"{option} ")

    code, out, err = _cli("tune", str(GROUND), "--method", method, "--grid", item, "--jobs", "1",
                          capsys=capsys)  # fmt: skip
    assert code == 2 and out == ""
    tune_says = _one_line("tune", err)
    # the same words, naming the grid axis as the user gave it instead of design's option
    assert tune_says == design_says.replace(option, f"--grid {item}", 1)


def test_a_range_reaching_out_of_bounds_names_its_first_bad_value(
    capsys: pytest.CaptureFixture[str], no_work: None
) -> None:
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid",
                          "phase_margin=50:120:5", capsys=capsys)  # fmt: skip
    assert code == 2 and out == ""
    message = _one_line("tune", err)
    assert message.startswith("--grid phase_margin=50:120:5 must be in (0, 89] degrees")
    assert message.endswith("got 90")  # 50, 55, …, 85 are fine; 90 is the first beyond 89


@pytest.mark.parametrize(
    ("grid", "says"),
    [
        ("phase_margin=nan", "--grid phase_margin=nan: the values must be finite numbers"),
        ("phase_margin=50:inf:5", "--grid phase_margin=50:inf:5: the values must be finite"),
        ("phase_margin=-inf", "the values must be finite numbers"),
        ("phase_margin=50:75:0", "--grid phase_margin=50:75:0: STEP must be > 0, got 0"),
        ("phase_margin=50:75:-5", "STEP must be > 0, got -5"),
        ("phase_margin=75:50:5", "--grid phase_margin=75:50:5: START 75 is above STOP 50"),
        ("phase_margin=", "--grid phase_margin=: expected START:STOP:STEP or one VALUE"),
        ("phase_margin=50::5", "--grid phase_margin=50::5: expected START:STOP:STEP"),
        ("phase_margin=50:75", "--grid phase_margin=50:75: expected START:STOP:STEP"),
        ("phase_margin=fifty", "--grid phase_margin=fifty: the values must be numbers"),
        ("phase_margin=50,phase_margin=60", "--grid: axis 'phase-margin' is given twice"),
        ("overshoot=2", "--grid: bad axis 'overshoot=2' for --method pi"),
        ("phase_margin=50:75:1e-320", "more than 1000 settings"),
        ("phase_margin=1:89:0.01", "--grid gives 61607 settings, more than 1000"),  # 8801 × 7
    ],
)
def test_a_malformed_grid_is_one_line(
    capsys: pytest.CaptureFixture[str], no_work: None, grid: str, says: str
) -> None:
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid", grid, capsys=capsys)
    assert code == 2 and out == ""
    assert says in _one_line("tune", err)


def _unstable_model(path: Path) -> float:
    """A copy of ground.toml whose motor a has a pole outside the unit circle; its |z|."""
    text = GROUND.read_text(encoding="utf-8")
    text = text.replace("theta = [-0.9356, 0.2173,", "theta = [-1.9356, 0.9173,", 1)
    path.write_text(text, encoding="utf-8")
    # Ω/V = (a z + b) / (z³ + c z² + d z): the poles are the roots of z² + c z + d
    return float(max(abs(np.roots([1.0, -1.9356, 0.9173]))))


@pytest.mark.parametrize("method", ["pi", "poles"])
def test_an_unstable_model_is_refused_as_design_refuses_it(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, no_work: None, method: str
) -> None:
    model = tmp_path / "unstable.toml"
    radius = _unstable_model(model)
    assert radius > 1.0
    code, out, err = _cli("design", str(model), "--method", method, capsys=capsys)
    assert code == 2 and out == ""
    design_says = _one_line("design", err)
    code, out, err = _cli("tune", str(model), "--method", method, "--jobs", "1", capsys=capsys)
    assert code == 2 and out == ""
    assert _one_line("tune", err) == design_says
    assert design_says.startswith(f"{model}: motor a's model is unstable")
    assert f"|z| = {radius:.4g}" in design_says


def test_a_missing_model_file_is_designs_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, no_work: None
) -> None:
    missing = str(tmp_path / "nothere.toml")
    _, _, design_err = _cli("design", missing, "--method", "pi", capsys=capsys)
    code, out, err = _cli("tune", missing, "--method", "pi", capsys=capsys)
    assert code == 2 and out == ""
    assert _one_line("tune", err) == _one_line("design", design_err)


def test_a_reference_no_motor_follows_is_runs_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    no_work: None,
) -> None:  # fmt: skip
    """1000 rad/s is beyond twice what the ground model's motors reach at 12 V (DC gain × 12 V,
    about 24 rad/s): every setting would only saturate, and run refuses it."""
    monkeypatch.chdir(tmp_path)
    code, out, run_err = _cli("run", "--fast", "--model", str(GROUND), "--reference", "step:1000",
                              "--rerun", "off", capsys=capsys)  # fmt: skip
    assert code == 2 and out == ""
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--reference", "step:1000",
                          capsys=capsys)  # fmt: skip
    assert code == 2 and out == ""
    assert _one_line("tune", err) == _one_line("run", run_err)
    assert not list(tmp_path.iterdir())  # nothing written by either


def test_a_setting_only_its_design_refuses_stays_a_row(capsys: pytest.CaptureFixture[str]) -> None:
    """65° at 2 Hz needs Kp < 0 on the ground model (design refuses it, for that setting
    alone); 65° at 4 Hz is designed. Both are rows, the command succeeds."""
    code, _, design_err = _cli("design", str(GROUND), "--method", "pi", "--phase-margin", "65",
                               "--crossover-hz", "2", capsys=capsys)  # fmt: skip
    assert code == 2 and "a PI cannot give 65° phase margin at 2 Hz" in design_err
    code, out, _ = _cli("tune", str(GROUND), "--method", "pi", "--grid",
                        "phase_margin=65,crossover_hz=2:4:2", "--duration", "0.5", "--jobs", "1",
                        capsys=capsys)  # fmt: skip
    assert code == 0
    rows = [line for line in out.splitlines() if re.match(r"^.{5}\s+[12]\s", line)]
    assert len(rows) == 2
    assert sum(line.rstrip().endswith("infeasible") for line in rows) == 1
    assert "#1: motor a: a PI cannot give 65° phase margin at 2 Hz" in out


_VALUE = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=32),
    st.sampled_from([0.0, 1e-9, 45.0, 89.0, 89.5, 99.9, 100.0, 0.02, 3.0, 49.9, 50.0]),
)


@st.composite
def _grid_items(draw: st.DrawFn) -> tuple[str, str]:
    method = draw(st.sampled_from(sorted(AXES)))
    items = []
    for axis in draw(st.lists(st.sampled_from(AXES[method]), max_size=3)):
        if draw(st.booleans()):
            items.append(f"{axis.name}={draw(_VALUE)!r}")
        else:
            start, span, step = draw(_VALUE), draw(_VALUE), draw(_VALUE)
            items.append(f"{axis.name}={start!r}:{start + span!r}:{step!r}")
    return method, ",".join(items)


@given(_grid_items())
@settings(max_examples=300, deadline=None)
def test_a_grid_is_refused_in_one_line_or_every_value_is_designable(case: tuple[str, str]) -> None:
    """Whatever the spec: one line, or values that design's request check accepts (no design
    is refused for a value out of its option's range)."""
    method, spec = case
    try:
        axes = parse_grid(spec, method)
    except InputError as exc:
        message = str(exc)
        axes = {}
    if not axes:
        assert "\n" not in message and message.startswith("--grid")
        return
    assert 1 <= np.prod([len(v) for v in axes.values()]) <= 1000
    for name, values in axes.items():
        for v in values:
            assert np.isfinite(v)
            DesignRequest(method=method, **{FIELDS[name]: v}).check()  # raises if out of range
