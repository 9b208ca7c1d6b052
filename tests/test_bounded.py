"""Bounded work: every option that sets the size of a computation is range-checked first.

Each refusal goes through the command line (in process) with the command's expensive step
patched to raise: the refusal has to come, in one line and exit 2, before that step is reached
(no wall clock involved). The limits themselves are stated in each command's --help.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import pytest

import cartctl
from cartctl.cli import main

ROOT = Path(__file__).resolve().parents[1]
GROUND = str(ROOT / "models" / "ground.toml")


class WorkStartedError(Exception):
    """Raised by a patched expensive step: the refusal came too late."""


@pytest.fixture(scope="module", autouse=True)
def _every_module_imported_first() -> None:
    """Every cartctl module imported before the first stand-in: a module first imported while one
    is on (a command's lazy import of a module that does ``from cartctl.plants.factory import
    make_plant`` at its top) would keep the stand-in for the rest of the session."""
    for info in pkgutil.walk_packages(cartctl.__path__, "cartctl."):
        if not info.name.endswith("__main__"):  # runs the command line
            importlib.import_module(info.name)


def _forbid(monkeypatch: pytest.MonkeyPatch, *targets: str) -> None:
    """Make each ``module:attribute`` raise :class:`WorkStartedError` when called."""

    def refuse(*_args: object, **_kwargs: object) -> None:
        raise WorkStartedError("the expensive step ran before the refusal")

    for target in targets:
        module, _, name = target.partition(":")
        monkeypatch.setattr(importlib.import_module(module), name, refuse)


def _refusal(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own usage errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    assert code == 2, err
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"cartctl {argv[0]}: error: ")
    return lines[0]


DESIGN_WORK = ("cartctl.data.modelfile:load_models", "cartctl.design.make:design_models")
TUNE_WORK = ("cartctl.data.modelfile:load_models", "cartctl.tune.engine:run_grid",
             "cartctl.tune.grid:parse_grid")  # fmt: skip
TUNE_GRID_WORK = ("cartctl.data.modelfile:load_models", "cartctl.tune.engine:run_grid")
IDENTIFY_WORK = ("cartctl.data.read:read_trace", "cartctl.identification.pipeline:identify")
PLANT_WORK = ("cartctl.plants.factory:make_plant",)
CART_WORK = ("cartctl.link.virtual_cart:VirtualCart", "cartctl.plants.factory:make_plant")

CASES = [
    # design: the delay sets the state's size (500 ticks took 76 s of CPU before the refusal)
    (["design", GROUND, "--method", "pi", "--extra-delay", "500"], "--extra-delay", DESIGN_WORK),
    (["design", GROUND, "--method", "poles", "--extra-delay", "51"], "at most 50", DESIGN_WORK),
    (["design", GROUND, "--method", "pi", "--loop-delay", "101"], "--loop-delay", DESIGN_WORK),
    (["design", GROUND, "--method", "pi", "--phase-margin", "120"], "--phase-margin", DESIGN_WORK),
    (["design", GROUND, "--method", "pi", "--disturbance-v", "50"], "--disturbance-v",
     DESIGN_WORK),
    # tune: options first, before the grid is even built
    (["tune", GROUND, "--method", "pi", "--extra-delay", "500"], "--extra-delay", TUNE_WORK),
    (["tune", GROUND, "--method", "pi", "--duration", "61"], "--duration", TUNE_WORK),
    (["tune", GROUND, "--method", "pi", "--duration", "1e9"], "--duration", TUNE_WORK),
    (["tune", GROUND, "--method", "pi", "--jobs", "65"], "--jobs", TUNE_WORK),
    (["tune", GROUND, "--method", "pi", "--jobs", "0"], "--jobs", TUNE_WORK),
    (["tune", GROUND, "--method", "pi", "--robust", "--plants", "10001"], "--plants", TUNE_WORK),
    (["tune", GROUND, "--method", "pi", "--robust", "--plants", "10000", "--duration", "2"],
     "plant-ticks per motor", TUNE_WORK),
    (["tune", GROUND, "--method", "pi", "--robust", "--actuation-ms", ",".join(["3"] * 21)],
     "--actuation-ms takes at most 20", TUNE_WORK),
    # tune: the grid's size, before the model is loaded or anything runs
    (["tune", GROUND, "--method", "pi", "--grid", "phase_margin=1:89:0.01"], "--grid gives",
     TUNE_GRID_WORK),
    (["tune", GROUND, "--method", "pi", "--grid", "phase_margin=10:89:0.1,crossover_hz=3",
      "--duration", "60"], "ticks, more than", TUNE_GRID_WORK),
    (["tune", GROUND, "--method", "poles", "--robust", "--plants", "5000", "--grid",
      "settling_time=0.05:0.5:0.001,overshoot=1"], "plant-ticks, more than", TUNE_GRID_WORK),
    # identify: the orders set the regression's size; checked before a trace is read
    (["identify", "x.csv", "--na", "51"], "--na", IDENTIFY_WORK),
    (["identify", "x.csv", "--nb", "1000"], "--nb", IDENTIFY_WORK),
    (["identify", "x.csv", "--na", "6", "--nb", "5", "--method", "oe"], "--method oe takes na + nb",
     IDENTIFY_WORK),
    (["identify", "x.csv", "--orders", "na=1:10,nb=1:10,nk=1:4"], "--orders", IDENTIFY_WORK),
    (["identify", "x.csv", "--orders", "na=1:51"], "--orders", IDENTIFY_WORK),
    (["identify", "x.csv", "--delay", "51"], "--delay", IDENTIFY_WORK),
    (["identify", "x.csv", "--loop-delay", "51"], "--loop-delay", IDENTIFY_WORK),
    (["identify", "x.csv", "--prefilter", "butter", "--order", "13"], "--order", IDENTIFY_WORK),
    # commission's tuning workers
    (["commission", "physics", "--jobs", "65"], "--jobs", PLANT_WORK),
    # durations and repetitions: already bounded at 24 h of signal
    (["run", "--fast", "--duration", "1e9", "--rerun", "off"], "--duration", PLANT_WORK),
    (["excite", "--plant", "sim", "--signal", "square", "--amplitude", "5", "--cycles",
      "100000000", "--out", "y.csv"], "cycles", PLANT_WORK),
    (["excite", "--plant", "sim", "--signal", "prbs", "--amplitude", "5", "--duration", "1e9",
      "--out", "y.csv"], "--duration", PLANT_WORK),
    (["monitor", "virtual", "--duration", "1e9"], "--duration", CART_WORK),
    (["virtual-cart", "--duration", "1e300"], "--duration", CART_WORK),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "names", "work"), CASES, ids=lambda v: " ".join(v)[:60] if isinstance(v, list) else None)  # fmt: skip
def test_a_bounded_option_is_refused_before_the_work(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    argv: list[str],
    names: str,
    work: tuple[str, ...],
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.csv").write_text("time_s,voltage_a,voltage_b,speed_a,speed_b\n0,0,0,0,0\n")
    _forbid(monkeypatch, *work)
    assert names in _refusal(capsys, argv)


@pytest.mark.parametrize("command", ["design", "tune"])
@pytest.mark.parametrize(("key", "value"), [("nk", 500), ("na", 51), ("nb", 51)])
def test_a_model_file_of_a_huge_order_is_refused_before_designing(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    command: str,
    key: str,
    value: int,
) -> None:
    """A design's state grows with the model's orders and delay (nk = 500 ran for minutes)."""
    text = (ROOT / "models" / "ground.toml").read_text(encoding="utf-8")
    na_nb = {"na": 2, "nb": 2, key: value}
    theta = [0.1] * (na_nb["na"] + na_nb["nb"])  # as many coefficients as the orders say
    head, _, _ = text.partition("[motors.a]")
    model = tmp_path / "big.toml"
    model.write_text(head + f"[motors.a]\ntheta = {theta}\nna = {na_nb['na']}\nnb = "
                     f"{na_nb['nb']}\nnk = {na_nb.get('nk', 2)}\n",
                     encoding="utf-8")  # fmt: skip
    _forbid(monkeypatch, "cartctl.design.make:design_models", "cartctl.tune.engine:run_grid")
    line = _refusal(capsys, [command, str(model), "--method", "pi"])
    assert f"{model}: {key} in [motors.a] must be in" in line and f"got {value}" in line


@pytest.mark.parametrize(
    ("command", "limits"),
    [
        ("design", ["0..50", "at most 100", "(0, 89]"]),
        ("tune", ["at most 1000 settings", "at most 60 s", "0..50", "1..64", "1..10000"]),
        ("identify", ["0..50", "1..50", "1..12", "na + nb up to 10", "up to 40000"]),
        ("commission", ["1..64"]),
    ],
)
def test_the_limits_are_in_the_help(
    capsys: pytest.CaptureFixture[str], command: str, limits: list[str]
) -> None:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())  # argparse's line breaks undone
    for limit in limits:
        assert limit in text, limit
