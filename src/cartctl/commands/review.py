"""``cartctl review FILE.rrd [--web] [--screenshot FILE.png]``: a recorded run in the Rerun viewer.

The last stage of the pipeline (run → logs/ → review). The recording is streamed into a viewer
together with the project's layout (:func:`cartctl.sinks.rerun_layout.blueprint`), so recordings
made without a layout, or with an older one, show the same plots. ``review RUN.csv [--json]
[--compare OTHER.csv]`` recomputes the run metrics from CSV traces instead (see
:mod:`cartctl.sinks.summary`).
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import os
import signal
import socket
import subprocess
import tempfile
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

from cartctl.errors import CartctlError, DataFileError, InputError, MissingFileError
from cartctl.jsonout import dumps

if TYPE_CHECKING:  # rerun takes ~0.6 s to import: only the review itself loads it
    import rerun as rr
    from rerun.chunk import RrdReader, StoreEntry
    from rerun.experimental import ViewerClient

VULKAN_HINT = "apt-get install mesa-vulkan-drivers libvulkan1"
SCREENSHOT_WINDOW = "1600x900"
"""Size of the headless viewer's window for ``--screenshot`` (logical points; the PNG may be
larger on a high-DPI scale)."""

_QUIET = ("--expect-data-soon", "--hide-welcome-screen")  # no welcome screen in the picture
_VIEWER_START_TIMEOUT_S = 20.0
_LOAD_TIMEOUT_S = 30.0


class ViewerError(CartctlError, RuntimeError):
    """The viewer could not be started, or could not render."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "review",
        help="open a recorded run in the Rerun viewer (or the metrics of a CSV trace)",
        description=(
            "Open a Rerun recording (.rrd) in the viewer with the project's layout: per motor, "
            "speed with reference and estimate above the voltage, then the loop timing. --web "
            "serves the web viewer instead, --screenshot renders the layout headless to a PNG. "
            "Given a CSV trace, print its run metrics instead (--json, --compare)."
        ),
    )
    p.add_argument("recording", metavar="FILE.rrd|RUN.csv", help="a recording or a CSV trace")
    view = p.add_mutually_exclusive_group()
    view.add_argument(
        "--web",
        action="store_true",
        help="serve the web viewer and print its URL; runs until Ctrl-C",
    )
    view.add_argument(
        "--screenshot",
        metavar="FILE.png",
        help=f"render the layout headless and save a picture (needs Vulkan: {VULKAN_HINT})",
    )
    p.add_argument(
        "--json", action="store_true", help="CSV traces: print one JSON object instead of a table"
    )
    p.add_argument("--compare", metavar="OTHER.csv", help="CSV traces: a second run to set beside")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Dispatch on the file's suffix: ``.rrd`` to the viewer, ``.csv`` to the trace metrics."""
    path = Path(args.recording)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _review_csv(args)
    if suffix != ".rrd":
        raise InputError(
            f"review takes a Rerun recording (.rrd) or a CSV trace (.csv), got '{path}'"
        )
    if args.json or args.compare:
        raise InputError("--json and --compare apply to CSV traces, not to .rrd recordings")
    if args.screenshot:
        out = screenshot(path, Path(args.screenshot))
        print(f"saved {out}")
        return 0
    if args.web:
        serve_web(path)
        return 0
    url = open_in_viewer(path)
    print(f"opened {path} in the Rerun viewer ({url})")
    return 0


def _review_csv(args: argparse.Namespace) -> int:
    """``cartctl review RUN.csv [--compare OTHER.csv] [--json]``: the run metrics from traces."""
    if args.web or args.screenshot:
        raise InputError("--web and --screenshot apply to .rrd recordings, not to CSV traces")
    from cartctl.data import read_trace
    from cartctl.sinks.summary import format_summary, trace_metrics

    paths = [args.recording] + ([args.compare] if getattr(args, "compare", None) else [])
    summaries = []
    for path in paths:
        trace = read_trace(path)
        summary = trace_metrics(trace.columns(), trace.period_s)
        summary["trace"] = str(path)
        summaries.append(summary)
    if args.json:
        print(dumps(summaries[0] if len(summaries) == 1 else {"runs": summaries}))
        return 0
    print("\n\n".join(format_summary(s) for s in summaries))
    return 0


def read_recording(path: Path) -> tuple[RrdReader, StoreEntry]:
    """Open a ``.rrd`` file and find its (first) recording.

    Raises
    ------
    MissingFileError
        No such file.
    DataFileError
        Not a readable recording, or one holding no recording store.
    """
    from rerun.chunk import RrdReader

    if not path.is_file():
        raise MissingFileError(path, "recording")
    try:
        reader = RrdReader(path)
        entries = reader.recordings()
    except (RuntimeError, ValueError, OSError) as exc:
        raise DataFileError(path, f"not a readable Rerun recording ({exc})") from None
    if not entries:
        raise DataFileError(path, "holds no recording (a blueprint file?)")
    return reader, entries[0]


def _stream(reader: RrdReader, entry: StoreEntry, rec: rr.RecordingStream) -> dict[str, int]:
    """Send the layout, then every chunk of the recording, into ``rec``; waits until sent.

    Returns
    -------
    dict of str to int
        The last time on each timeline (ns for durations, the index for sequences).
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    from cartctl.sinks.rerun_layout import blueprint

    ends: dict[str, int] = {}
    chunks = list(reader.stream(store=entry))
    for chunk in chunks:
        if chunk.is_static or chunk.is_empty:
            continue
        batch = chunk.to_record_batch()
        for name in chunk.timeline_names:
            last = pc.max(batch.column(name).cast(pa.int64())).as_py()
            if last is not None:
                ends[name] = max(ends.get(name, last), last)
    rec.send_blueprint(blueprint())
    rec.send_chunks(chunks)
    rec.flush(timeout_sec=_LOAD_TIMEOUT_S)
    return ends


def _new_stream(entry: StoreEntry) -> rr.RecordingStream:
    import rerun as rr

    # A fresh recording id: reviewing the same file twice into one viewer gives two recordings
    # rather than one with every row twice. The file's own properties chunk travels with the data.
    return rr.RecordingStream(
        entry.application_id, recording_id=uuid.uuid4(), send_properties=False
    )


# -- the three ways to look at it ------------------------------------------------------------


def open_in_viewer(path: Path) -> str:
    """Stream the recording and the layout into the native viewer (spawned if none is running).

    Returns
    -------
    str
        The viewer's gRPC address.
    """
    import rerun as rr

    from cartctl.sinks.viewer import VIEWER_PORT, display_available, viewer_reachable

    reader, entry = read_recording(path)
    if not display_available():
        raise ViewerError(
            "no display to open the viewer on (DISPLAY/WAYLAND_DISPLAY unset): "
            "use --web, or --screenshot FILE.png"
        )
    executable = _executable()
    url = f"rerun+http://127.0.0.1:{VIEWER_PORT}/proxy"
    rec = _new_stream(entry)
    try:
        # Connects to a viewer already listening on the port instead of starting a second one.
        rr.spawn(port=VIEWER_PORT, connect=False, executable_path=executable, recording=rec)
        if not viewer_reachable(url):
            raise ViewerError(f"the viewer ({executable}) did not start on this display")
        rec.connect_grpc(url)
        _stream(reader, entry, rec)
    except ViewerError:
        raise
    except (RuntimeError, ConnectionError, OSError) as exc:
        raise ViewerError(f"could not hand the recording to the viewer at {url}: {exc}") from None
    finally:
        rec.disconnect()
    return url


def serve_web(path: Path, *, wait: Callable[[str], None] | None = None) -> str:
    """Serve the recording and the layout to the web viewer, print its URL, and block.

    Parameters
    ----------
    path : Path
        The ``.rrd`` file.
    wait : callable, optional
        Called with the URL while serving; returning stops the servers. Default: until Ctrl-C.

    Returns
    -------
    str
        The web viewer's URL.
    """
    import rerun as rr

    reader, entry = read_recording(path)
    rec = _new_stream(entry)
    try:
        grpc_url = rec.serve_grpc(grpc_port=_free_port(), server_memory_limit="25%")
        _stream(reader, entry, rec)
        web_port = _free_port()
        rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=grpc_url)
        url = f"http://127.0.0.1:{web_port}/?url={quote(grpc_url, safe='')}"
        print(f"web viewer: {url}", flush=True)
        if wait is None:
            print("serving until Ctrl-C", flush=True)
            with contextlib.suppress(KeyboardInterrupt):
                threading.Event().wait()
        else:
            wait(url)
    finally:
        rec.disconnect()
    return url


def screenshot(path: Path, out: Path, *, window: str = SCREENSHOT_WINDOW) -> Path:
    """Render the recording with the layout in a headless viewer and save a PNG.

    The time cursor is put at the end of the ``time`` timeline, paused, before the picture is
    taken. Needs a Vulkan driver (on Debian/Ubuntu without a GPU: ``mesa-vulkan-drivers`` and
    ``libvulkan1``). Takes about 1–3 s.

    Parameters
    ----------
    path : Path
        The ``.rrd`` file.
    out : Path
        The picture (``.png``); parent folders are created.
    window : str
        Viewer window size, ``WIDTHxHEIGHT`` in logical points.

    Returns
    -------
    Path
        ``out``, absolute.

    Raises
    ------
    ViewerError
        The viewer could not start or render (one line naming the Vulkan packages).
    """
    if out.suffix.lower() != ".png":
        raise InputError(f"--screenshot writes a PNG picture, got '{out}'")
    reader, entry = read_recording(path)
    executable = _executable()
    out = out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    port = _free_port()
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    with tempfile.TemporaryDirectory(prefix="cartctl-review-") as tmp:
        log_path = Path(tmp) / "viewer.log"
        with log_path.open("wb") as log:
            # Its own session, so the wrapper script and the viewer it starts stop together.
            viewer = subprocess.Popen(
                [executable, "--headless", "--port", str(port), "--window-size", window, *_QUIET],
                env={**os.environ, "RERUN_APP_ONLY": "true"},
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        rec = _new_stream(entry)
        try:
            client = _wait_for_viewer(url, port, viewer, log_path)
            rec.connect_grpc(url)
            ends = _stream(reader, entry, rec)
            _pause_at_end(client, ends)
            client.save_screenshot(str(out))
        except ViewerError:
            raise
        except (RuntimeError, ConnectionError, OSError, TimeoutError) as exc:
            reason = _viewer_failure(log_path) or str(exc).splitlines()[0]
            raise ViewerError(
                f"the headless viewer could not render ({reason}); it needs a Vulkan driver: "
                f"{VULKAN_HINT}"
            ) from None
        finally:
            rec.disconnect()
            _stop(viewer)
    if not out.is_file():
        raise ViewerError(
            f"the viewer did not write {out}; it needs a Vulkan driver: {VULKAN_HINT}"
        )
    return out


# -- helpers -------------------------------------------------------------------------------

_ICD_DIRS = (
    "/usr/share/vulkan/icd.d",
    "/usr/local/share/vulkan/icd.d",
    "/etc/vulkan/icd.d",
)


def vulkan_available() -> bool:
    """Whether a Vulkan loader and at least one driver (ICD) are installed, as ``--screenshot`` needs.

    Looks for ``libvulkan`` and for an ICD manifest (``*.json``) in the standard folders or in
    ``VK_ICD_FILENAMES`` / ``VK_DRIVER_FILES``. Mesa's software driver (lavapipe) counts.
    """
    import ctypes.util

    if ctypes.util.find_library("vulkan") is None:
        return False
    listed = os.environ.get("VK_DRIVER_FILES") or os.environ.get("VK_ICD_FILENAMES")
    if listed:
        return any(Path(f).is_file() for f in listed.split(os.pathsep) if f)
    return any(glob.glob(os.path.join(d, "*.json")) for d in _ICD_DIRS)


def _executable() -> str:
    from cartctl.sinks.viewer import viewer_executable

    executable = viewer_executable()
    if executable is None:
        raise ViewerError(
            "the Rerun viewer ('rerun') was not found next to Python or on PATH; "
            "install rerun-sdk in this environment"
        )
    return executable


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_for_viewer(
    url: str, port: int, viewer: subprocess.Popen[bytes], log_path: Path
) -> ViewerClient:
    """Wait until the viewer has drawn a frame, or fail with the reason it gave."""
    from rerun.experimental import ViewerClient

    deadline = time.monotonic() + _VIEWER_START_TIMEOUT_S
    client: ViewerClient | None = None
    while time.monotonic() < deadline:
        if viewer.poll() is not None:
            reason = _viewer_failure(log_path) or f"it exited with code {viewer.returncode}"
            raise ViewerError(
                f"the headless viewer could not start ({reason}); it needs a Vulkan driver: "
                f"{VULKAN_HINT}"
            )
        try:
            if client is None:
                with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                    pass
                client = ViewerClient.connect(url)
            client.take_screenshot(max_size=16)  # answers only once a frame has been drawn
            return client
        except (OSError, ConnectionError, RuntimeError):
            time.sleep(0.05)
    raise ViewerError(
        f"the headless viewer did not start within {_VIEWER_START_TIMEOUT_S:g} s; "
        f"it needs a Vulkan driver: {VULKAN_HINT}"
    )


def _pause_at_end(client: ViewerClient, ends: dict[str, int]) -> None:
    """Wait until the viewer holds the whole recording, then pause the time cursor at its end.

    Parameters
    ----------
    client : ViewerClient
    ends : dict of str to int
        The recording's last time per timeline (as :func:`_stream` returns).
    """
    import numpy as np

    name = "time" if "time" in ends else next(iter(ends), None)
    deadline = time.monotonic() + _LOAD_TIMEOUT_S
    while name is not None:
        state = client.get_state()
        timelines = state.recordings[0].timelines if state.recordings else []
        shown = next((t for t in timelines if t.name == name), None)
        if not state.loading and shown is not None and (shown.end or -1) >= ends[name]:
            if shown.time_type == "sequence":
                client.set_time(name, sequence=ends[name], play_state="paused")
            else:
                client.set_time(
                    name, duration=np.timedelta64(ends[name], "ns"), play_state="paused"
                )
            break
        if time.monotonic() > deadline:
            raise TimeoutError(f"the recording did not load within {_LOAD_TIMEOUT_S:g} s")
        time.sleep(0.05)
    time.sleep(0.8)  # frames for the plots to fit their axes and the start-up notices to fade


def _viewer_failure(log_path: Path) -> str | None:
    """The viewer's own one-line reason for failing, if its log has one."""
    try:
        text = log_path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    for marker in ("No graphics adapter", "graphics adapter", "Vulkan", "panicked"):
        for line in text.splitlines():
            if marker in line:
                return line.strip()[:200]
    return None


def _stop(viewer: subprocess.Popen[bytes]) -> None:
    """Stop the viewer this command started: its session (the wrapper script and the binary)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            if os.name == "posix":
                os.killpg(viewer.pid, sig)
            else:
                viewer.kill()
        except ProcessLookupError:
            pass
        try:
            viewer.wait(5.0)
            return
        except subprocess.TimeoutExpired:
            continue
