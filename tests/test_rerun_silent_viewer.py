"""A Rerun viewer that accepts the connection but never answers (suspended with Ctrl-Z): closing
the recording must not wait for it for ever (the SDK's ``disconnect()`` and its exit hook do,
rerun-io/rerun#12620). A socket server in the test accepts and reads nothing; the run ends with
its summary, its whole files and one warning line naming the viewer."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

from cartctl import stopping
from cartctl.sinks import rerun_problems
from cartctl.sinks.rerun_sink import RecordingWarning, RerunSink

HANG_TIMEOUT_S = 60.0  # far above the run's own bounded wait (seconds)

# the wait for the viewer is on the wall clock (5 s; monitor's cart behind a pseudo-terminal); the
# file waits behind the stream in the SDK: it is cut to its whole messages, with no footer
pytestmark = [pytest.mark.realtime, pytest.mark.filterwarnings("ignore:RRD file has no footer")]


@pytest.fixture
def silent_viewer() -> Iterator[str]:
    """The gRPC address of a server that accepts connections and never reads or answers."""
    server = socket.create_server(("127.0.0.1", 0))
    accepted: list[socket.socket] = []

    def accept() -> None:
        while True:
            try:
                accepted.append(server.accept()[0])
            except OSError:  # closed at the test's end
                return

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    yield f"rerun+http://127.0.0.1:{server.getsockname()[1]}/proxy"
    server.shutdown(socket.SHUT_RDWR)  # wakes accept() (close alone does not)
    server.close()
    for conn in accepted:
        conn.close()
    thread.join(5)


def _cartctl(workdir: Path, *argv: str) -> tuple[str, str]:
    """Run ``cartctl ARGV`` to its end (a failure if it hangs); its stdout and stderr."""
    process = subprocess.Popen(
        [sys.executable, "-m", "cartctl", *argv], cwd=workdir, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        out, err = process.communicate(timeout=HANG_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        pytest.fail(f"cartctl {argv[0]} hung on a viewer that never answers")
    assert process.returncode == 0, err
    assert "Traceback" not in err
    return out, err


def test_run_streaming_to_a_silent_viewer_ends(workdir: Path, silent_viewer: str, rrd_rows) -> None:
    out, err = _cartctl(workdir, "run", "--fast", "--duration", "1", "--json",
                        "--rerun", "connect", "--connect-url", silent_viewer, "--name", "s")  # fmt: skip
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("cartctl run: warning: Rerun recording"), err
    assert f"the Rerun viewer at {silent_viewer} did not answer" in lines[0]
    summary = json.loads(out)
    rows = rrd_rows(workdir / "logs" / "s.rrd")  # readable, every row
    assert rows["motor/a/voltage"] == summary["ticks"] > 90


def test_monitor_streaming_to_a_silent_viewer_ends(
    workdir: Path, silent_viewer: str, rrd_rows
) -> None:
    out, err = _cartctl(workdir, "monitor", "virtual", "--duration", "1", "--json",
                        "--rerun", "connect", "--connect-url", silent_viewer, "--name", "m")  # fmt: skip
    warned = [line for line in err.splitlines() if line.startswith("cartctl monitor:")]
    assert len(warned) == 1 and f"the Rerun viewer at {silent_viewer} did not answer" in warned[0]
    frames = json.loads(out)["frames"]
    assert rrd_rows(workdir / "logs" / "m.rrd")["gpio/speed_a"] == frames > 50


def _sink_with_rows(path: Path, url: str) -> RerunSink:
    sink = RerunSink("connect", path, connect_url=url)
    sink.open(["time_s", "speed_a"])
    for k in range(50):
        sink.write([k * 0.01, float(k)])
    return sink


def test_closing_waits_briefly_for_a_silent_viewer_after_a_stop_signal(
    tmp_path: Path, silent_viewer: str, monkeypatch: pytest.MonkeyPatch, rrd_rows
) -> None:
    sink = _sink_with_rows(tmp_path / "r.rrd", silent_viewer)
    monkeypatch.setattr(stopping, "received", lambda: 2)  # a Ctrl-C came: leave at once
    closing = threading.Thread(target=sink.close, daemon=True)  # the old SDK call never returned
    start = time.monotonic()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        closing.start()
        closing.join(HANG_TIMEOUT_S)
    assert not closing.is_alive(), "closing the recording hung on a viewer that never answers"
    assert time.monotonic() - start < 3.0
    assert [type(w.message) for w in caught] == [RecordingWarning]
    assert "did not answer: its stream may be incomplete" in str(caught[0].message)
    assert rrd_rows(tmp_path / "r.rrd")["motor/a/speed"] == 50


def test_review_into_a_silent_viewer_ends(
    tmp_path: Path, silent_viewer: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    from cartctl.cli.commands.review import recording

    path = tmp_path / "r.rrd"
    sink = RerunSink("save", path)
    sink.open(["time_s", "speed_a"])
    sink.write([0.0, 1.0])
    sink.close()
    # the silent server is the viewer already running at the viewer's port: review uses it
    monkeypatch.setattr(recording, "VIEWER_URL", silent_viewer)
    monkeypatch.setattr(recording, "VIEWER_PORT", int(silent_viewer.split(":")[2].split("/")[0]))
    monkeypatch.setattr(recording, "LOAD_TIMEOUT_S", 1.0)  # its flush gives up, as it did
    monkeypatch.setattr(rerun_problems, "VIEWER_WAIT_S", 1.0)  # and the connection's end too
    monkeypatch.setenv("DISPLAY", ":99")
    raised: list[BaseException] = []

    def review() -> None:
        try:
            recording.open_in_viewer(path)
        except BaseException as exc:
            raised.append(exc)

    reviewing = threading.Thread(target=review, daemon=True)  # the old SDK call never returned
    reviewing.start()
    reviewing.join(HANG_TIMEOUT_S)
    assert not reviewing.is_alive(), "review hung on a viewer that never answers"
    assert [type(e) for e in raised] == [recording.ViewerError]
    assert f"the Rerun viewer at {silent_viewer} did not answer" in str(raised[0])
