"""One loop, one delay: the joint delay choice, the traces' meta files, the model's loop delay, and
the loop delay design takes from it."""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import ModelFile, Provenance, load_models, save_models
from cartctl.data.trace import (
    Trace,
    agreed_loop_delay,
    meta_path,
    read_trace_meta,
    write_trace,
    write_trace_meta,
)
from cartctl.errors import DataFileError, InputError
from cartctl.identification.orders import CLOSE_FRACTION, DelayEstimate, joint_delay
from cartctl.model import ArxModel
from cartctl.signals import prbs

GROUND_A = [-0.9356, 0.2173, 0.6466, -0.07751]  # the report's equation 12, motor a


def _evidence(rms: tuple[float, ...], equations: int = 100) -> DelayEstimate:
    n = len(rms)
    best = int(np.argmin(rms))
    return DelayEstimate(best + 1, tuple(range(1, n + 1)), rms, (0.0,) * n, (0.0,) * n, equations)


def test_joint_delay_is_the_weighted_geometric_mean() -> None:
    # a alone prefers nk = 1, b alone nk = 2; by hand: sqrt(1.0·10) = 3.162, sqrt(1.5·6) = 3.0
    joint = joint_delay({"a": _evidence((1.0, 1.5)), "b": _evidence((10.0, 6.0))})
    assert joint.evidence_rad_s == pytest.approx((math.sqrt(10.0), 3.0))
    assert joint.nk == 2 and not joint.too_close and joint.note() is None
    assert joint.motors["a"].nk == 2 and joint.motors["a"].nk_alone == 1
    assert joint.motors["b"].nk == 2 and joint.motors["b"].nk_alone is None
    # weights by equation count: a with 3x b's equations → (1^3·10)^(1/4) = 1.778 < (1.5^3·6)^(1/4)
    weighted = joint_delay({"a": _evidence((1.0, 1.5), 300), "b": _evidence((10.0, 6.0), 100)})
    assert weighted.evidence_rad_s[0] == pytest.approx(10.0**0.25)
    assert weighted.nk == 1


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_one_motors_scale_does_not_change_the_choice(scale: float) -> None:
    b = tuple(scale * r for r in (10.0, 6.0, 20.0))
    assert joint_delay({"a": _evidence((1.0, 1.5, 3.0)), "b": _evidence(b)}).nk == 2


def test_a_close_call_takes_the_larger_delay_and_says_so() -> None:
    within = 1.0 + CLOSE_FRACTION / 2
    joint = joint_delay({"a": _evidence((1.0, within**2, 5.0)), "b": _evidence((1.0, 1.0, 5.0))})
    assert joint.close == (1, 2) and joint.too_close
    assert joint.nk == 2  # nk = 1 is the best, but not by enough to call
    note = joint.note()
    assert note is not None and "too close to call" in note and "nk = 2" in note
    assert "\n" not in note
    assert joint.to_dict()["too_close"] is True


def test_trace_meta_round_trip_and_agreement(tmp_path: Path) -> None:
    trace = tmp_path / "logs" / "ground.csv"
    assert meta_path(trace) == tmp_path / "logs" / "ground.meta.toml"
    assert read_trace_meta(trace) is None  # no meta file: unknown, not an error
    write_trace_meta(trace, plant="physics (preset ground)", loop_delay_ticks=1, command="x")
    meta = read_trace_meta(trace)
    assert meta is not None and meta.loop_delay_ticks == 1 and meta.plant.startswith("physics")
    write_trace_meta(tmp_path / "unknown.csv", plant="serial", loop_delay_ticks=None)
    unknown = read_trace_meta(tmp_path / "unknown.csv")
    assert unknown is not None and unknown.loop_delay_ticks is None
    assert agreed_loop_delay({"g": meta, "u": unknown, "none": None}) == 1
    other = write_trace_meta(tmp_path / "serial.csv", plant="serial", loop_delay_ticks=3)
    with pytest.raises(InputError, match="different delays"):
        agreed_loop_delay({"g": meta, "s": read_trace_meta(tmp_path / "serial.csv")})
    other.write_text('format = "cartctl-trace-meta/1"\nloop_delay_ticks = "one"\n')
    with pytest.raises(DataFileError, match="loop_delay_ticks"):
        read_trace_meta(tmp_path / "serial.csv")


def _sim_trace(path: Path, nk: int, seed: int) -> Path:
    model = ArxModel.from_theta(GROUND_A, nk=nk)
    u = prbs(6.0, duration_s=6.0, seed=seed)
    y = model.simulate(u) + np.random.default_rng(seed).normal(0.0, 0.05, u.size)
    write_trace(Trace(np.arange(u.size) * 0.01, u, u, y, y), path)
    return path


def test_identify_refuses_traces_of_different_loops(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    one = _sim_trace(tmp_path / "one.csv", 2, 1)
    three = _sim_trace(tmp_path / "three.csv", 2, 2)
    write_trace_meta(one, plant="physics", loop_delay_ticks=1)
    write_trace_meta(three, plant="serial", loop_delay_ticks=3)
    assert main(["identify", str(one), str(three)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "different delays" in err and "one.csv" in err


def test_identify_carries_the_loop_delay_into_the_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _sim_trace(tmp_path / "x.csv", 2, 3)
    out = tmp_path / "m.toml"
    assert main(["identify", str(data), "--out", str(out)]) == 0  # no meta file: unknown
    assert load_models(out).loop_delay_ticks is None
    assert main(["identify", str(data), "--loop-delay", "1", "--out", str(out)]) == 0
    assert load_models(out).loop_delay_ticks == 1
    write_trace_meta(data, plant="physics", loop_delay_ticks=1)
    assert main(["identify", str(data), "--delay", "auto", "--out", str(out)]) == 0
    capsys.readouterr()
    models = load_models(out)
    assert models.loop_delay_ticks == 1
    assert models.motor("a").nk == models.motor("b").nk == 2  # one delay for both motors


def test_identify_says_why_the_loop_delay_is_unknown(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A meta file without a loop delay (a killed cart excite leaves one) was reported as 'no
    .meta.toml beside the data'."""
    data = _sim_trace(tmp_path / "x.csv", 2, 4)
    assert main(["identify", str(data)]) == 0
    assert "loop delay: unknown (no .meta.toml beside the data;" in capsys.readouterr().out
    write_trace_meta(data, plant="cart on /dev/ttyACM0", loop_delay_ticks=None)
    assert main(["identify", str(data)]) == 0
    assert "loop delay: unknown (the .meta.toml beside the data records none;" in (
        capsys.readouterr().out
    )


def _model_file(tmp_path: Path, nk: int, loop_delay_ticks: int | None) -> Path:
    model = ArxModel.from_theta(GROUND_A, nk=nk)
    prov = Provenance(source="test", created="2026-11-25")
    path = tmp_path / f"nk{nk}-loop{loop_delay_ticks}.toml"
    save_models(ModelFile({"a": model, "b": model}, prov, loop_delay_ticks=loop_delay_ticks), path)
    return path


Design = Callable[[pytest.CaptureFixture[str], int, "int | None"], tuple[Path, Path, int, str]]


@pytest.fixture(scope="module")
def poles_design(tmp_path_factory: pytest.TempPathFactory) -> Design:
    """``cartctl design --method poles`` of the test model with (nk, loop delay), run once per
    module for each pair: (model file, controller file, exit code, stderr). The (1, 1) design is
    the one test_design_takes_the_loop_delay_from_the_model checks and the one
    test_a_design_for_the_models_loop_runs_on_its_sim_plant runs."""
    folder = tmp_path_factory.mktemp("designs")
    done: dict[tuple[int, int | None], tuple[Path, Path, int, str]] = {}

    def design(
        capsys: pytest.CaptureFixture[str], nk: int, recorded: int | None
    ) -> tuple[Path, Path, int, str]:
        if (nk, recorded) not in done:
            model = _model_file(folder, nk, recorded)
            out = folder / f"c-nk{nk}-loop{recorded}.toml"
            capsys.readouterr()
            code = main(["design", str(model), "--method", "poles", "--out", str(out)])
            done[nk, recorded] = (model, out, code, capsys.readouterr().err)
        return done[nk, recorded]

    return design


@pytest.mark.parametrize(
    ("nk", "recorded", "designed", "note"),
    [
        (2, 1, 1, None),  # the report's timing: nk = loop delay + 1
        (1, 1, 1, "lands within the tick"),  # the model's first input term covers it
        (1, None, 0, None),  # an older model file: nk - 1, as before
        (3, 1, 2, "does not fit the loop delay 1"),  # neither 1 nor 2: nk - 1, with the reason
    ],
)
def test_design_takes_the_loop_delay_from_the_model(
    capsys: pytest.CaptureFixture[str],
    poles_design: Design,
    nk: int,
    recorded: int | None,
    designed: int,
    note: str | None,
) -> None:
    _, out, code, err = poles_design(capsys, nk, recorded)
    assert code == 0, err
    doc = tomllib.loads(out.read_text(encoding="utf-8"))
    assert doc["loop_delay_ticks"] == designed
    if note is None:
        assert "note:" not in err
    else:
        assert note in err and len(err.strip().splitlines()) == 1


def test_design_adds_the_extra_delay_to_the_models_loop(tmp_path: Path) -> None:
    model = _model_file(tmp_path, 2, 1)
    out = tmp_path / "c.toml"
    assert (
        main(["design", str(model), "--method", "pi", "--extra-delay", "2", "--out", str(out)]) == 0
    )
    assert tomllib.loads(out.read_text(encoding="utf-8"))["loop_delay_ticks"] == 3


def test_a_model_file_with_a_bad_loop_delay_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _model_file(tmp_path, 2, 1)
    path.write_text(path.read_text().replace("loop_delay_ticks = 1", "loop_delay_ticks = -1"))
    assert main(["inspect", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "loop_delay_ticks" in err


def test_a_design_for_the_models_loop_runs_on_its_sim_plant(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], poles_design: Design
) -> None:
    model, out, code, _ = poles_design(capsys, 1, 1)  # nk = 1, loop delay 1: nk - 1 would say 0
    assert code == 0
    argv = ["run", "--plant", "sim", "--model", str(model), "--controller", str(out), "--fast",
            "--rerun", "off", "--duration", "0.5", "--out", str(tmp_path / "logs"), "--json"]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    summary = json.loads(capsys.readouterr().out)
    assert summary["loop_delay_ticks"] == 1
    meta = read_trace_meta(summary["trace"])  # run's trace carries its loop too
    assert meta is not None and meta.loop_delay_ticks == 1
