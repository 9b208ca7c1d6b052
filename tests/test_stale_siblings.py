"""A trace written over an earlier run's name leaves none of that run's files beside it: its
recording (``X.rrd``) or meta file (``X.meta.toml``) would pass for the new trace's
(``review X.rrd`` showed the old run; ``identify X.csv`` took its loop delay)."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from cartctl.cli import main
from cartctl.errors import PlantError

EXCITE = ["excite", "--amplitude", "5", "--cycles", "1"]


def _ok(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    code = main(argv)
    assert code == 0, capsys.readouterr().err
    capsys.readouterr()


def test_excite_removes_an_earlier_runs_recording(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("x.rrd").write_bytes(b"an earlier run's recording")
    _ok(capsys, [*EXCITE, "--out", "x.csv"])
    assert sorted(os.listdir()) == ["x.csv", "x.meta.toml"]
    _ok(capsys, [*EXCITE, "--out", "z.rrd"])  # a trace named so is not removed as a recording
    assert Path("z.rrd").read_text(encoding="utf-8").startswith("time_s,")


def test_convert_removes_an_earlier_runs_recording(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)
    _ok(capsys, [*EXCITE, "--out", "x.csv"])
    Path("y.rrd").write_bytes(b"an earlier run's recording")
    _ok(capsys, ["convert", "x.csv", "--out", "y.csv"])
    assert not Path("y.rrd").exists()
    Path("x.rrd").write_bytes(b"the trace's own recording")  # converted onto itself: kept
    _ok(capsys, ["convert", "x.csv", "--out", "./x.csv"])
    assert Path("x.rrd").read_bytes() == b"the trace's own recording"


def _fails_in_reset(make_plant: Callable[..., Any]) -> Callable[..., Any]:
    def make(*args: Any, **kwargs: Any) -> Any:
        plant, description = make_plant(*args, **kwargs)
        plant.reset = lambda: (_ for _ in ()).throw(PlantError("the plant failed in its reset"))
        return plant, description

    return make


def _stop_signal(start: Callable[..., Any]) -> Callable[..., Any]:
    def signalled(*args: Any, **kwargs: Any) -> Any:
        os.kill(os.getpid(), signal.SIGTERM)  # the handler raises at once
        return start(*args, **kwargs)

    return signalled


@pytest.mark.parametrize("stop", ["plant", "signal"])
def test_a_run_stopped_before_its_first_tick_leaves_an_earlier_runs_files(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, stop: str
) -> None:
    """The meta file was written before the loop: a run that failed in the plant's reset (or was
    stopped as the loop started) put its meta file beside the earlier run's trace and recording."""
    from cartctl.plants import factory
    from cartctl.runtime.loop import ControlLoop

    monkeypatch.chdir(tmp_path)
    argv = ["run", "--fast", "--duration", "0.3", "--out", ".", "--name", "x"]
    _ok(capsys, [*argv, "--rerun", "save"])
    before = {name: Path(name).read_bytes() for name in os.listdir()}
    assert sorted(before) == ["x.csv", "x.meta.toml", "x.rrd"]
    if stop == "plant":
        monkeypatch.setattr(factory, "make_plant", _fails_in_reset(factory.make_plant))
    else:
        monkeypatch.setattr(ControlLoop, "start", _stop_signal(ControlLoop.start))
    code = main([*argv, "--rerun", "off", "--model", "models/air.toml"])
    (line,) = capsys.readouterr().err.splitlines()
    assert code == (1 if stop == "plant" else 143), line
    assert {name: Path(name).read_bytes() for name in os.listdir()} == before


RUN = ["run", "--fast", "--duration", "0.3", "--rerun", "off", "--out", ".", "--name", "x"]
MONITOR = ["monitor", "virtual", "--duration", "0.3", "--rerun", "off", "--out", ".", "--name", "x"]
EXCITATION = "x.csv holds an excitation; cartctl {} replaces only {}: give another {} or remove it"


@pytest.mark.parametrize(
    ("first", "then", "line"),
    [
        ([*EXCITE, "--out", "x.csv"], RUN, EXCITATION.format("run", "a run's trace", "--name")),
        (
            [*EXCITE, "--out", "x.csv"],
            MONITOR,
            EXCITATION.format(
                "monitor", "a trace without a .meta.toml (a monitor's, a converted log)", "--name"
            ),
        ),
        (
            RUN,
            [*EXCITE, "--out", "x.csv"],
            "x.csv holds a run's trace; cartctl excite replaces only an excitation: give another "
            "--out or remove it",
        ),
        (
            None,
            RUN,
            "x.csv holds a trace without a .meta.toml (a monitor's, a converted log); "
            "cartctl run replaces only a run's trace: give another --name or remove it",
        ),
    ],
    ids=["run-over-excitation", "monitor-over-excitation", "excite-over-run", "run-over-no-meta"],
)
def test_a_trace_another_command_recorded_is_not_replaced(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    first: list[str] | None,
    then: list[str],
    line: str,
) -> None:
    """run --name x replaced the excitation x.csv (identify's data) and its meta file, silently:
    run, excite and monitor replace only a trace of their own kind, as the meta file tells."""
    monkeypatch.chdir(tmp_path)
    if first is None:  # a monitor's trace, a converted QRC log: no meta file
        Path("x.csv").write_text("time_s,voltage_a,speed_a\n0.0,0.0,0.0\n", encoding="utf-8")
    else:
        _ok(capsys, first)
    before = {name: Path(name).read_bytes() for name in os.listdir()}
    code = main(then)
    out, err = capsys.readouterr()
    assert (code, out, err.count("\n")) == (2, "", 1), err
    assert err.rstrip().endswith(line)
    assert {name: Path(name).read_bytes() for name in os.listdir()} == before
    if first is not None:
        _ok(capsys, first)  # a trace of its own kind is still replaced


@pytest.mark.parametrize(
    "left",
    [
        {"x.csv": ""},  # a full disk as the header was written
        {"x.csv": "time_s,voltage_a,speed_a\n", "x.meta.toml": ""},  # ... as the meta file was
        {"x.csv": "time_s,voltage_a,speed_a\n"},  # a kill between the header and the meta file
    ],
    ids=["empty", "header-and-empty-meta", "header-only"],
)
@pytest.mark.parametrize("then", [RUN, [*EXCITE, "--out", "x.csv"]], ids=["run", "excite"])
def test_a_trace_without_rows_is_replaced_by_the_same_command(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    left: dict[str, str],
    then: list[str],
) -> None:
    """A run or an excitation stopped by a full disk before its first row left a trace without
    rows (and no meta file, or an empty one): the same command again was refused (a trace
    'without a .meta.toml', or the empty meta file), though it holds nothing to lose."""
    monkeypatch.chdir(tmp_path)
    for name, text in left.items():
        Path(name).write_text(text, encoding="utf-8")
    _ok(capsys, then)
    assert Path("x.meta.toml").read_text(encoding="utf-8").startswith("# cartctl")


def test_a_run_whose_meta_file_names_no_controller_is_still_a_run(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A run's meta file names its controller since 9082b29; one written before (the same
    format, its command line 'cartctl run ...') was taken for an excitation: run --name over
    it was refused and excite --out replaced it."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.argv", ["cartctl", *RUN])  # the command line its meta file keeps
    _ok(capsys, RUN)
    meta = Path("x.meta.toml")
    lines = meta.read_text(encoding="utf-8").splitlines(keepends=True)
    meta.write_text("".join(x for x in lines if not x.startswith(("controller", "model"))))
    before = {name: Path(name).read_bytes() for name in os.listdir()}
    assert main([*EXCITE, "--out", "x.csv"]) == 2
    assert (
        capsys.readouterr()
        .err.rstrip()
        .endswith(
            "x.csv holds a run's trace; cartctl excite replaces only an excitation: give another "
            "--out or remove it"
        )
    )
    assert {name: Path(name).read_bytes() for name in os.listdir()} == before
    _ok(capsys, RUN)
