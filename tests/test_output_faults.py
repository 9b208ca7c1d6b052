"""Output paths checked before anything runs; a write that fails during a run is a fault.

The full disk is injected without root: a trace or recording that is a link to ``/dev/full``
(every write fails with ENOSPC), a file-size limit (``RLIMIT_FSIZE``: writes past it fail with
EFBIG, mid-row), and a raw file with a byte budget under the CSV sink. The command-line cases run
``cartctl`` in a process of its own, so stderr is what a user sees (the Rerun SDK's own logger
included).
"""

from __future__ import annotations

import errno
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.cli import main
from cartctl.data.outputs import check_output_folder
from cartctl.data.read import read_trace
from cartctl.errors import InputError, OutputError
from cartctl.model import ArxModel
from cartctl.plants.sim import ArxPlant
from cartctl.reference import reference_signal
from cartctl.runtime.loop import ControlLoop, MemorySink
from cartctl.runtime.pi import PiController
from cartctl.sinks.csv_sink import CsvSink

ROOT = Path(__file__).resolve().parents[1]
FULL = Path("/dev/full")
# the device: as root, a command can leave a plain file there, which takes every write (seen)
needs_dev_full = pytest.mark.skipif(
    not FULL.is_char_device(), reason="no /dev/full device on this system"
)
RAW_SDK_LINE = re.compile(r"\x1b\[|\bERROR\b|\bWARN\b|re_log|re_sdk")


def cartctl(
    *argv: str, cwd: Path, file_size_limit: int | None = None
) -> subprocess.CompletedProcess:
    """``cartctl ARGV`` in a process of its own (the user's RUST_LOG left out)."""
    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    limit = None
    if file_size_limit is not None:
        import resource

        def limit() -> None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_size_limit, file_size_limit))

    return subprocess.run(
        [sys.executable, "-m", "cartctl", *argv],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=120, preexec_fn=limit,
    )  # fmt: skip


def tree(folder: Path) -> list[str]:
    """Everything under ``folder`` (relative paths), to show a check left nothing behind."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# -- 1. output paths are checked before anything runs ---------------------------------------------


def _file(tmp: Path) -> tuple[str, str]:
    (tmp / "notes.txt").write_text("mine\n")
    return str(tmp / "notes.txt"), "is a file, not a folder"


def _under_a_file(tmp: Path) -> tuple[str, str]:
    (tmp / "notes.txt").write_text("mine\n")
    return str(tmp / "notes.txt" / "runs"), f"cannot create: {tmp / 'notes.txt'} is a file"


def _proc(tmp: Path) -> tuple[str, str]:
    return "/proc/cartctl", "cannot create: /proc takes no new files or folders"


def _sys(tmp: Path) -> tuple[str, str]:
    return "/sys/kernel", "cannot write there: permission denied"


@pytest.mark.parametrize(
    "case",
    [
        _file,
        _under_a_file,
        pytest.param(_proc, marks=pytest.mark.skipif(not Path("/proc/self").exists(), reason="no /proc")),
        pytest.param(_sys, marks=pytest.mark.skipif(not Path("/sys/kernel").is_dir(), reason="no /sys")),
    ],
)  # fmt: skip
def test_run_refuses_an_output_folder_before_it_connects_a_plant(
    tmp_path: Path, case, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out, why = case(tmp_path)
    monkeypatch.chdir(tmp_path)
    before = tree(tmp_path)
    # a port that does not exist: had the plant come first, the message would be about it
    assert main(["run", "--plant", "serial:/dev/cartctl-no-such-port", "--out", out]) == 2
    assert capsys.readouterr() == ("", f"cartctl run: error: --out {out}: {why}\n")
    assert tree(tmp_path) == before  # no logs/, no meta file
    if case is _file:
        assert (tmp_path / "notes.txt").read_text() == "mine\n"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A trace and a recording for the commands that read one (written by cartctl itself)."""
    folder = tmp_path_factory.mktemp("inputs")
    assert (
        main(["excite", "--amplitude", "3", "--cycles", "1", "--out", str(folder / "ex.csv")]) == 0
    )
    assert main(["run", "--fast", "--duration", "0.3", "--rerun", "save", "--out", str(folder),
                 "--name", "r"]) == 0  # fmt: skip
    return folder


def _commands(i: Path, blocked: Path) -> list[tuple[list[str], str, Path, str]]:
    """(argv, option, path given, command) of every command writing files; ``blocked`` is a file."""
    f = blocked / "x"
    return [
        (["excite", "--amplitude", "3", "--out", str(f / "ex.csv")], "--out", f / "ex.csv", "excite"),
        (["monitor", "virtual", "--out", str(f)], "--out", f, "monitor"),
        (["commission", "physics", "--out", str(f)], "--out", f, "commission"),
        (["convert", str(i / "ex.csv"), "--out", str(f / "c.csv")], "--out", f / "c.csv", "convert"),
        (["identify", str(i / "ex.csv"), "--out", str(f / "m.toml")], "--out", f / "m.toml", "identify"),
        (["identify", str(i / "ex.csv"), "--report", str(f)], "--report", f, "identify"),
        (["validate", "models/ground.toml", str(i / "ex.csv"), "--plot", str(f / "v.png")], "--plot",
         f / "v.png", "validate"),
        (["linearity", *[str(i / "ex.csv")] * 3, "--plot", str(f / "l.png")], "--plot", f / "l.png",
         "linearity"),
        (["design", "models/ground.toml", "--method", "pi", "--out", str(f / "c.toml")], "--out",
         f / "c.toml", "design"),
        (["design", "models/ground.toml", "--method", "pi", "--report", str(f)], "--report", f, "design"),
        (["tune", "models/ground.toml", "--method", "pi", "--choose", "1", "--out", str(f / "t.toml")],
         "--out", f / "t.toml", "tune"),
        (["tune", "models/ground.toml", "--method", "pi", "--plot", str(f / "t.png")], "--plot",
         f / "t.png", "tune"),
        (["export", "controllers/pi.toml", "--arduino", "--out", str(f / "c.h")], "--out", f / "c.h",
         "export"),
        (["export", "controllers/pi.toml", "--mat", str(f / "c.mat")], "--mat", f / "c.mat", "export"),
        (["review", str(i / "r.rrd"), "--screenshot", str(f / "s.png")], "--screenshot", f / "s.png",
         "review"),
    ]  # fmt: skip


@pytest.mark.parametrize("index", range(15))
def test_every_writing_command_checks_its_output_first(
    index: int, inputs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    monkeypatch.chdir(ROOT)  # the shipped models and controllers
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where a folder is wanted\n")
    argv, option, path, command = _commands(inputs, blocked)[index]
    before = tree(tmp_path)
    assert main(argv) == 2
    _, err = capsys.readouterr()
    assert err == f"cartctl {command}: error: {option} {path}: cannot create: {blocked} is a file\n"
    assert tree(tmp_path) == before


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    shape=st.lists(st.tuples(st.sampled_from(["d", "f"]), st.sampled_from("abc")), max_size=4),
    ask=st.lists(st.sampled_from("abc"), min_size=1, max_size=4),
)
def test_a_folder_check_leaves_the_tree_as_it_was(
    tmp_path_factory: pytest.TempPathFactory, shape: list[tuple[str, str]], ask: list[str]
) -> None:
    """Whatever the folders and files in the way: the check passes exactly when a file can be
    made in the folder afterwards, names --out and the folder when it refuses, and changes
    nothing on disk."""
    root = tmp_path_factory.mktemp("tree")
    here = root
    for kind, name in shape:  # a chain: folders, or a file that ends it
        here = here / name
        if kind == "f":
            here.write_text("x")
            break
        here.mkdir()
    before = tree(root)
    folder = root.joinpath(*ask)
    refusal = ""
    try:
        check_output_folder(folder, "--out")
    except InputError as exc:
        refusal = str(exc)
    assert tree(root) == before
    assert refusal == "" or refusal.startswith(f"--out {folder}: ")
    ok = refusal == ""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "probe").write_text("")
        can = True
    except OSError:
        can = False
    assert ok == can


# -- 2. a failed write is a fault ------------------------------------------------------------------


def _one_line(stderr: str) -> str:
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert not RAW_SDK_LINE.search(stderr), stderr
    return lines[0]


@needs_dev_full
def test_a_trace_on_a_full_disk_stops_the_run(tmp_path: Path, rrd_rows) -> None:
    (tmp_path / "dfull.csv").symlink_to(FULL)
    result = cartctl("run", "--fast", "--rerun", "save", "--out", str(tmp_path), "--name", "dfull",
                     "--json", cwd=ROOT)  # fmt: skip
    assert result.returncode == 1
    trace = tmp_path / "dfull.csv"
    assert _one_line(result.stderr) == (
        f"cartctl run: error: {trace} is incomplete: No space left on device (after 0 rows); "
        "the motors were stopped"
    )
    summary = json.loads(result.stdout)
    assert summary["trace"] == str(trace)  # the JSON output's key, and beside it what it holds
    assert summary["trace_complete"] is False
    assert summary["incomplete"] == {str(trace): "No space left on device (after 0 rows)"}
    assert summary["recording_complete"] is True
    assert summary["ticks"] == 1  # the stop row only: the loop never ticked
    rows = rrd_rows(tmp_path / "dfull.rrd")  # the recording is whole: its footer reads
    assert rows["motor/a/voltage"] == 1


@needs_dev_full
def test_a_recording_on_a_full_disk_is_a_fault_without_the_sdk_lines(tmp_path: Path) -> None:
    (tmp_path / "dfull.rrd").symlink_to(FULL)
    result = cartctl("run", "--fast", "--rerun", "save", "--out", str(tmp_path), "--name", "dfull",
                     cwd=ROOT)  # fmt: skip
    assert result.returncode == 1
    rrd = tmp_path / "dfull.rrd"
    assert _one_line(result.stderr) == (
        f"cartctl run: error: {rrd} is incomplete: No space left on device (after 0 rows); "
        "the motors were stopped"
    )
    assert f"recording: {rrd} (INCOMPLETE: No space left on device" in result.stdout
    assert f"trace: {tmp_path / 'dfull.csv'}\n" in result.stdout  # whole: nothing said
    last = (tmp_path / "dfull.csv").read_text().splitlines()[-1].split(",")
    assert (float(last[1]), float(last[2])) == (0.0, 0.0)  # the stop row: zero volts


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE and its EFBIG as on Linux")
def test_a_write_cut_mid_run_leaves_whole_rows_and_says_how_many(tmp_path: Path) -> None:
    result = cartctl("run", "--fast", "--rerun", "off", "--duration", "60", "--out", str(tmp_path),
                     "--name", "cut", "--json", cwd=ROOT, file_size_limit=40_000)  # fmt: skip
    assert result.returncode == 1
    line = _one_line(result.stderr)
    found = re.fullmatch(
        rf"cartctl run: error: {re.escape(str(tmp_path / 'cut.csv'))} is incomplete: "
        r"File too large \(after (\d+) rows\); the motors were stopped",
        line,
    )
    assert found, line
    text = (tmp_path / "cut.csv").read_text()
    assert text.endswith("\n")
    lines = text.splitlines()
    widths = {len(row.split(",")) for row in lines}
    assert widths == {len(lines[0].split(","))}  # no half row
    assert len(lines) - 1 == int(found.group(1))
    summary = json.loads(result.stdout)
    assert summary["trace_complete"] is False
    assert summary["ticks"] < 6000  # it stopped at the failure, not after 60 s


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE and its EFBIG as on Linux")
@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # what a cut recording lacks
def test_a_recording_cut_by_a_full_disk_still_reads(tmp_path: Path, rrd_rows) -> None:
    """The SDK's write stops mid-message at the limit; the file is cut back to its last whole
    message, so the recording so far reads (a reader fails on a message cut short)."""
    result = cartctl("run", "--fast", "--rerun", "save", "--duration", "60", "--out", str(tmp_path),
                     "--name", "cut", cwd=ROOT, file_size_limit=150_000)  # fmt: skip
    assert result.returncode == 1
    rrd = tmp_path / "cut.rrd"
    assert f"{rrd} is incomplete" in _one_line(result.stderr)
    assert 0 < rrd.stat().st_size < 150_000
    assert rrd_rows(rrd)["motor/a/voltage"] > 0


@needs_dev_full
def test_excite_on_a_full_disk_is_a_fault(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """In this process: excite loads no Rerun SDK (no stderr of its own to see), nor a limit."""
    (tmp_path / "ex.csv").symlink_to(FULL)
    monkeypatch.chdir(ROOT)
    code = main(["excite", "--amplitude", "3", "--cycles", "1", "--out", str(tmp_path / "ex.csv")])
    assert code == 1
    assert _one_line(capsys.readouterr().err) == (
        f"cartctl excite: error: {tmp_path / 'ex.csv'} is incomplete: No space left on device "
        "(after 0 rows)"
    )
    assert not (tmp_path / "ex.meta.toml").exists()


@needs_dev_full
def test_commission_on_a_full_disk_is_a_fault_naming_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stage's figure on a full disk: exit 1 and the file named (it was exit 2, the code of a
    user's mistake, and a bare 'No space left on device'), the summary says where it stopped."""
    out = tmp_path / "c"
    out.mkdir()
    (out / "checks.png").symlink_to(FULL)
    from cartctl.commission import report

    monkeypatch.chdir(ROOT)
    code = main(["commission", "physics", "--out", str(out), "--jobs", "1"])
    assert code == 1
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"cartctl commission: checks: {out / 'checks.png'} is incomplete: No space left on device"
    )
    assert "At stage **checks**" in (out / "summary.md").read_text(encoding="utf-8")
    assert (out / "checks.csv").is_file() and not (out / "model.toml").exists()
    (out / "summary.md.tmp").symlink_to(FULL)  # the summary itself on a full disk
    with pytest.raises(OSError, match="No space left on device"):
        report.Report(out / "summary.md", "t").add("x", "y")
    assert not (out / "summary.md.tmp").exists()  # no half-written temporary left


class BudgetFile:
    """A raw file that takes ``budget`` bytes (a last write only in part), then fails: ENOSPC."""

    def __init__(self, real, budget: int) -> None:
        self.real, self.budget = real, budget

    def write(self, data) -> int:
        if self.budget <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = min(len(data), self.budget)
        self.budget -= n
        return self.real.write(bytes(data[:n]))

    def fileno(self) -> int:
        return self.real.fileno()

    def close(self) -> None:
        self.real.close()


class FillingCsvSink(CsvSink):
    """The CSV sink on a disk with ``budget`` bytes left after the header."""

    def __init__(self, path: Path, budget: int) -> None:
        super().__init__(path, flush_every=10)
        self.budget = budget

    def open(self, columns) -> None:
        super().open(columns)
        self._file = BudgetFile(self._file, self.budget)  # type: ignore[assignment]


class CommandedPlant(ArxPlant):
    """The ARX plant, remembering every command."""

    def __init__(self) -> None:
        model = ArxModel.from_theta([-0.9356, 0.2173, 0.6466, -0.07751])
        super().__init__(model, model)
        self.commands: list[tuple[float, float]] = []

    def step(self, voltage_a_v: float, voltage_b_v: float):
        self.commands.append((voltage_a_v, voltage_b_v))
        return super().step(voltage_a_v, voltage_b_v)


def _run(loop: ControlLoop, ticks: list[int]) -> None:
    """Tick, idle, tick … as an executor does; finish on every exit path."""
    loop.start()
    try:
        k = 0
        while loop.tick(k, 0.0, 0.0):
            loop.idle()
            ticks.append(k)
            k += 1
    finally:
        loop.finish()


def test_the_loop_stops_on_a_failed_write_with_zero_volts_and_whole_rows(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    sink, memory, plant = FillingCsvSink(path, budget=3000), MemorySink(), CommandedPlant()
    n = 1000
    refs = {m: reference_signal("step:10:0.1", n) for m in "ab"}
    loop = ControlLoop(plant, {m: PiController(0.2, 13.0, 0.01) for m in "ab"}, refs,
                       [sink, memory], now_s=lambda: 0.0)  # fmt: skip
    ticks: list[int] = []
    with pytest.raises(OutputError) as raised:
        _run(loop, ticks)
    assert len(ticks) < n - 1  # stopped at the failure
    assert plant.commands[-1] == (0.0, 0.0)  # the normal stop path: zero volts
    assert loop.state.zero_volts_sent
    volts = memory.arrays()["voltage_a"]
    assert volts[-1] == 0.0 and np.any(volts[:-1] != 0.0)
    assert [e.path for e in loop.state.incomplete] == [path]
    data = path.read_bytes()
    assert data.endswith(b"\n")  # cut back to the last whole row
    rows = data.decode().splitlines()
    assert {len(r.split(",")) for r in rows} == {len(rows[0].split(","))}
    assert raised.value.rows == sink.rows_written == len(rows) - 1 > 0
    assert (
        str(raised.value)
        == f"{path} is incomplete: No space left on device (after {len(rows) - 1} rows)"
    )


@needs_dev_full
@pytest.mark.realtime  # the virtual cart behind a pseudo-terminal
def test_monitor_on_a_full_disk_is_a_fault(tmp_path: Path) -> None:
    (tmp_path / "m.csv").symlink_to(FULL)
    result = cartctl("monitor", "virtual", "--duration", "1", "--out", str(tmp_path), "--name", "m",
                     cwd=ROOT)  # fmt: skip
    assert result.returncode == 1
    assert not RAW_SDK_LINE.search(result.stderr), result.stderr
    lines = [line for line in result.stderr.splitlines() if not line.startswith("cart: ")]
    assert lines == [
        f"cartctl monitor: error: {tmp_path / 'm.csv'} is incomplete: No space left on device "
        "(after 0 rows)"
    ]  # the cart's own PRINT lines (``cart: …``) are what a monitor shows


@pytest.mark.parametrize(
    ("message", "why"),
    [
        ("Failed to encode LogMsg: Failed to write: No space left on device (os error 28)",
         "No space left on device"),
        ("Failed to write: File too large (os error 27)", "File too large"),
        ("File-writer thread shut down prematurely", "the recording's writer stopped"),
        ("transport error: connection refused", None),  # the viewer's side: not the file
    ],
)  # fmt: skip
def test_the_sdk_failure_is_read_into_the_file_reason(
    message: str, why: str | None, tmp_path: Path
) -> None:
    from cartctl.sinks.rerun_problems import file_failure

    assert file_failure(RuntimeError(message), tmp_path / "r.rrd") == why
    assert file_failure(RuntimeError(message), None) is None  # no file, no file failure


def test_the_sdk_logs_are_off_unless_the_user_asked(monkeypatch: pytest.MonkeyPatch) -> None:
    from cartctl.sinks import rerun_problems

    monkeypatch.setattr(rerun_problems, "_QUIETED", set())
    monkeypatch.delenv("RUST_LOG", raising=False)
    rerun_problems.quiet_sdk_logs()
    assert os.environ["RUST_LOG"] == "off"
    assert "RUST_LOG" not in rerun_problems.viewer_env()  # a viewer keeps its own log
    monkeypatch.setattr(rerun_problems, "_QUIETED", set())
    monkeypatch.setenv("RUST_LOG", "debug")
    rerun_problems.quiet_sdk_logs()
    assert os.environ["RUST_LOG"] == "debug"
    assert rerun_problems.viewer_env()["RUST_LOG"] == "debug"


def test_excite_keeps_the_ticks_before_a_fault_of_its_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """An error of cartctl itself in the 51st step (not a PlantError): zero volts, and the 51
    rows recorded are written, as for a plant's fault; it was a traceback and no trace at all."""
    step = ArxPlant.step
    calls = {"n": 0}

    def failing(self: ArxPlant, *args: float) -> object:
        calls["n"] += 1
        if calls["n"] == 51:
            raise RuntimeError("a bug")
        return step(self, *args)

    monkeypatch.setattr(ArxPlant, "step", failing)
    monkeypatch.chdir(ROOT)
    code = main(["excite", "--amplitude", "3", "--cycles", "1", "--out", str(tmp_path / "ex.csv")])
    assert code == 1
    assert capsys.readouterr().err.splitlines()[-1] == (
        "cartctl excite: error: internal error: RuntimeError: a bug; the trace holds the ticks "
        "recorded so far"
    )
    assert len(read_trace(tmp_path / "ex.csv")) == 51


@needs_dev_full
def test_identify_report_on_a_full_disk_is_a_fault_naming_the_file(
    inputs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """identify --report DIR with summary.md (written last) or a figure on a full disk: a bare
    'No space left on device', exit 2, the figures left without a word; now exit 1 naming the
    file, as the other commands' files on a full disk."""
    for name in ("summary.md", "io.png"):
        report = tmp_path / name.replace(".", "_")
        report.mkdir()
        (report / name).symlink_to(FULL)
        assert main(["identify", str(inputs / "ex.csv"), "--report", str(report)]) == 1
        assert capsys.readouterr().err == (
            f"cartctl identify: error: {report / name} is incomplete: No space left on device\n"
        )


def test_identify_report_whose_summary_is_a_folder_is_refused_first(
    inputs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A folder named summary.md in --report DIR: the model file and the figures were written,
    then 'Is a directory'; now one line before anything is written."""
    report = tmp_path / "r"
    (report / "summary.md").mkdir(parents=True)
    before = tree(tmp_path)
    argv = [
        "identify",
        str(inputs / "ex.csv"),
        "--report",
        str(report),
        "--out",
        str(tmp_path / "m.toml"),
    ]
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"cartctl identify: error: --report {report / 'summary.md'}: is a folder, not a file\n"
    )
    assert tree(tmp_path) == before


def test_a_screenshot_on_a_full_disk_is_a_fault_not_a_missing_driver(
    inputs: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The viewer failing to save the picture (its error, as rerun-sdk 0.2x words it for a full
    disk: seen on a 32 kB tmpfs) read 'the headless viewer could not render (<a raw log line of
    the viewer>); it needs a Vulkan driver'; it is exit 1 naming the file."""
    from rerun.experimental import ViewerClient

    from cartctl.cli.commands.review import recording

    if not recording.vulkan_available():
        pytest.skip("no Vulkan driver (apt-get install mesa-vulkan-drivers libvulkan1)")

    def full(self: object, file_path: str, view_id: object = None) -> None:
        raise ConnectionError(
            f"Failed to save screenshot to {file_path}: No space left on device (os error 28) "
            '(Internal)\n- metadata: {"content-type": "application/grpc"}'
        )

    monkeypatch.setattr(ViewerClient, "save_screenshot", full)
    out = tmp_path / "s.png"
    assert main(["review", str(inputs / "r.rrd"), "--screenshot", str(out)]) == 1
    assert capsys.readouterr().err == (
        f"cartctl review: error: {out} is incomplete: No space left on device\n"
    )


@needs_dev_full
@pytest.mark.parametrize(
    ("argv", "name"),
    [
        (["identify", "{i}/ex.csv", "--out", "{f}"], "m.toml"),
        (["design", "models/ground.toml", "--method", "pi", "--out", "{f}"], "c.toml"),
        (["design", "models/ground.toml", "--method", "pi", "--report", "{d}"], "design_a.png"),
        (["validate", "models/ground.toml", "{i}/ex.csv", "--plot", "{f}"], "v.png"),
        (["tune", "models/ground.toml", "--method", "pi", "--plot", "{f}"], "t.png"),
        (
            ["tune", "models/ground.toml", "--method", "pi", "--choose", "5", "--out", "{f}"],
            "t.toml",
        ),
        (["export", "controllers/pi.toml", "--arduino", "--out", "{f}"], "c.h"),
        (["export", "controllers/pi.toml", "--mat", "{f}"], "c.mat"),
        (["convert", "{i}/ex.csv", "--out", "{f}"], "c.csv"),
    ],
    ids=lambda v: v[0] + " " + v[-2] if isinstance(v, list) else v,
)
def test_a_file_on_a_full_disk_is_a_fault_naming_it(
    argv: list[str], name: str, inputs: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """A model, controller, figure, export or converted trace on a full disk was a bare 'No space
    left on device', exit 2 (a user's mistake), naming no file; it is exit 1 naming the file, as
    a run's trace."""
    monkeypatch.chdir(ROOT)
    (tmp_path / name).symlink_to(FULL)
    words = [w.format(i=inputs, f=tmp_path / name, d=tmp_path) for w in argv]
    assert main(words) == 1
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"cartctl {argv[0]}: error: {tmp_path / name} is incomplete: No space left on device"
    )
