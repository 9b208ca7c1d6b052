"""A ``.rrd`` recording read back (:func:`read_recording`) and streamed with the project's layout
(:func:`stream`) into a viewer: the native one, the web viewer (``--web``) or a headless one's
picture (``--screenshot FILE.png``, which needs a Vulkan driver: :func:`vulkan_available`)."""

from __future__ import annotations

import contextlib
import glob
import os
import re
import signal
import socket
import subprocess
import tempfile
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote
from uuid import uuid4

from cartctl.errors import CartctlError, DataFileError, InputError, MissingFileError, OutputError
from cartctl.sinks.rerun_problems import (
    VIEWER_PORT,
    VIEWER_URL,
    disconnect,
    display_available,
    viewer_env,
    viewer_executable,
    viewer_reachable,
)
from cartctl.stopping import held

if TYPE_CHECKING:  # rerun takes ~0.6 s to import: only the review itself loads it
    import pyarrow as pa
    import rerun as rr
    import rerun.blueprint as rrb
    from numpy.typing import NDArray
    from rerun.chunk import Chunk, RrdReader, StoreEntry
    from rerun.experimental import ViewerClient

    from cartctl.sinks.rerun_sink import Series

LOAD_TIMEOUT_S = 30.0  # longest wait for a viewer to take in (or show) the whole recording


def read_recording(path: Path) -> tuple[RrdReader, StoreEntry]:
    """Open a ``.rrd`` file and find its (first) recording."""
    from rerun.chunk import RrdReader

    if path.is_dir():
        raise DataFileError(path, "is a directory; expected a Rerun recording (.rrd)")
    if not path.is_file():
        raise MissingFileError(path, "recording")
    if path.stat().st_size == 0:
        raise DataFileError(path, "the file is empty; expected a Rerun recording (.rrd)")
    with warnings.catch_warnings(record=True) as said:  # the SDK's: shown if the file reads
        warnings.simplefilter("always")
        try:
            reader = RrdReader(path)
            entries = reader.recordings()
        except (RuntimeError, ValueError, OSError) as exc:
            raise DataFileError(path, f"not a readable Rerun recording ({exc})") from None
    if not entries:
        raise DataFileError(path, "holds no recording (a blueprint file?)")
    for w in said:
        warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return reader, entries[0]


def stream(
    reader: RrdReader, entry: StoreEntry, rec: rr.RecordingStream, *, extra: Series | None = None
) -> dict[str, int]:
    """Send the layout (:func:`layout`), every chunk of the recording (a monitor's motor signals
    in the run's styles), then ``extra`` (the smoothed speed, styled) into ``rec``; waits until
    sent. Returns the last time on each
    timeline (ns for durations, the index for sequences)."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import rerun as rr

    from cartctl.sinks.rerun_layout import review_styles
    from cartctl.sinks.rerun_sink import send_series

    ends: dict[str, int] = {}
    chunks = list(reader.stream(store=entry))
    for chunk, batch in batches(chunks):
        for name in chunk.timeline_names:
            last = pc.max(batch.column(name).cast(pa.int64())).as_py()
            if last is not None:
                ends[name] = max(ends.get(name, last), last)
    rec.send_blueprint(layout(chunks))
    rec.send_chunks(chunks)
    # a monitor's motor signals drawn in the run's colours
    for entity, style in review_styles(c.entity_path.lstrip("/") for c in chunks).items():
        rec.log(entity, rr.SeriesLines(colors=[style.color], widths=[style.width]), static=True)
    send_series(rec, extra or {})
    rec.flush(timeout_sec=LOAD_TIMEOUT_S)
    return ends


SCALARS = "Scalars:scalars"  # the column of a scalar series' values in a chunk


def batches(chunks: Iterable[Chunk]) -> Iterator[tuple[Chunk, pa.RecordBatch]]:
    """Each chunk that holds rows on a timeline, with its rows as a record batch."""
    for chunk in chunks:
        if not (chunk.is_static or chunk.is_empty):
            yield chunk, chunk.to_record_batch()


def scalar_series(
    chunks: Iterable[Chunk], timelines: Sequence[str] = ("tick", "time")
) -> dict[str, tuple[NDArray[Any], ...]]:
    """Per entity path of a scalar series with rows on ``timelines``: the rows' place on each
    (ns for a time) and their values, in the recording's order."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.compute as pc

    parts: dict[str, list[tuple[NDArray[Any], ...]]] = {}
    for chunk, batch in batches(chunks):
        if {*timelines, SCALARS} <= set(batch.schema.names):
            at = [
                batch.column(n).cast(pa.int64()).to_numpy(zero_copy_only=False) for n in timelines
            ]
            values = pc.list_element(batch.column(SCALARS), 0).to_numpy(zero_copy_only=False)
            parts.setdefault(chunk.entity_path.lstrip("/"), []).append((*at, values))
    return {
        path: tuple(np.concatenate(p) for p in zip(*pieces, strict=True))
        for path, pieces in parts.items()
    }


def scalar_stats(chunks: Iterable[Chunk]) -> tuple[dict[str, tuple[float, float]], set[str]]:
    """Per entity path of scalar series: the lowest and highest finite value, and the set of
    paths whose values are all whole numbers."""
    import numpy as np
    import pyarrow.compute as pc

    extremes: dict[str, tuple[float, float]] = {}
    fractional: set[str] = set()
    for chunk, batch in batches(chunks):  # every value of a row (a row may hold none, or two)
        if SCALARS not in batch.schema.names:
            continue
        values = pc.list_flatten(batch.column(SCALARS)).to_numpy(zero_copy_only=False)
        values = values[np.isfinite(values)]
        if not values.size:
            continue
        path = chunk.entity_path.lstrip("/")
        lo, hi = float(values.min()), float(values.max())
        old = extremes.get(path, (lo, hi))
        extremes[path] = (min(old[0], lo), max(old[1], hi))
        if np.any(values != np.round(values)):
            fractional.add(path)
    return extremes, set(extremes) - fractional


def layout(chunks: Sequence[Chunk]) -> rrb.Blueprint:
    """The layout of a recording: the run's (``motor/...``), the monitor's built from its labels
    (``gpio/...``), each with y ranges from the values; the run's plain layout otherwise."""
    from cartctl.sinks.rerun_layout import review_blueprint

    extremes, whole = scalar_stats(chunks)
    return review_blueprint(extremes, whole, {chunk.entity_path.lstrip("/") for chunk in chunks})


def new_stream(entry: StoreEntry) -> rr.RecordingStream:
    """A stream for ``entry``'s application under a fresh recording id (a file reviewed twice
    into one viewer gives two recordings, not every row twice)."""
    import rerun as rr

    return rr.RecordingStream(entry.application_id, recording_id=uuid4(), send_properties=False)


VULKAN_HINT = "apt-get install mesa-vulkan-drivers libvulkan1"
# the headless viewer's window (1600x900 logical points), no welcome screen in the picture
_WINDOW = ("--window-size", "1600x900", "--expect-data-soon", "--hide-welcome-screen")
_VIEWER_START_TIMEOUT_S = 20.0
_ICD_DIRS = ("/usr/share/vulkan/icd.d", "/usr/local/share/vulkan/icd.d", "/etc/vulkan/icd.d")


class ViewerError(CartctlError, RuntimeError):
    """The viewer could not be started, or could not render."""


def _needs_vulkan(what: str) -> ViewerError:
    return ViewerError(f"{what}; it needs a Vulkan driver: {VULKAN_HINT}")


def require_viewer() -> str:
    """The Rerun viewer executable (:class:`ViewerError` when there is none)."""
    executable = viewer_executable()
    if executable is None:
        raise ViewerError(
            "the Rerun viewer ('rerun') was not found next to Python or on PATH; "
            "install rerun-sdk in this environment"
        )
    return executable


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def open_in_viewer(path: Path, *, extra: Series | None = None) -> str:
    """Stream the recording, the layout and ``extra`` (series made from the recording: the
    smoothed speed) into the native viewer, spawned if none is running; returns its address."""
    import rerun as rr

    reader, entry = read_recording(path)
    if not display_available():
        raise ViewerError(
            "no display to open the viewer on (DISPLAY/WAYLAND_DISPLAY unset): "
            "use --web, or --screenshot FILE.png"
        )
    executable = require_viewer()
    rec = new_stream(entry)
    try:
        # Connects to a viewer already listening on the port instead of starting a second one.
        rr.spawn(port=VIEWER_PORT, connect=False, executable_path=executable, recording=rec)
        if not viewer_reachable(VIEWER_URL):
            raise ViewerError(f"the viewer ({executable}) did not start on this display")
        rec.connect_grpc(VIEWER_URL)
        stream(reader, entry, rec, extra=extra)
    except ViewerError:
        raise
    except (RuntimeError, ConnectionError, OSError) as exc:
        raise ViewerError(
            f"could not hand the recording to the viewer at {VIEWER_URL}: {exc}"
        ) from None
    finally:  # bounded: a viewer that took the connection may never answer (Ctrl-Z)
        try:
            disconnect(rec, VIEWER_URL, None)
        except TimeoutError as exc:
            raise ViewerError(str(exc)) from None
    return VIEWER_URL


def serve_web(
    path: Path, *, wait: Callable[[str], None] | None = None, extra: Series | None = None
) -> str:
    """Serve the recording, the layout and ``extra`` to the web viewer, print its URL and block
    until Ctrl-C (or until ``wait``, called with the URL, returns); returns the URL."""
    import rerun as rr

    reader, entry = read_recording(path)
    rec = new_stream(entry)
    try:
        grpc_url = rec.serve_grpc(grpc_port=free_port(), server_memory_limit="25%")
        stream(reader, entry, rec, extra=extra)
        web_port = free_port()
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


def screenshot(path: Path, out: Path, *, extra: Series | None = None) -> Path:
    """Render the recording, the layout and ``extra`` in a headless viewer (its own session,
    stopped after), with the time cursor paused at the end, and save the PNG ``out``; returns
    ``out``, absolute. Takes about 1–3 s."""
    if out.suffix.lower() != ".png":
        raise InputError(f"--screenshot writes a PNG picture, got '{out}'")
    reader, entry = read_recording(path)
    executable = require_viewer()
    out = out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    port = free_port()
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    with tempfile.TemporaryDirectory(prefix="cartctl-review-") as tmp:
        log_path = Path(tmp) / "viewer.log"
        viewer: subprocess.Popen[bytes] | None = None
        rec: rr.RecordingStream | None = None
        try:
            with held(), log_path.open("wb") as log:  # a stop signal waits until it is known
                viewer = subprocess.Popen(
                    [executable, "--headless", "--port", str(port), *_WINDOW],
                    env={**viewer_env(), "RERUN_APP_ONLY": "true"},
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            rec = new_stream(entry)
            client = _wait_for_viewer(url, viewer, log_path)
            rec.connect_grpc(url)
            ends = stream(reader, entry, rec, extra=extra)
            _pause_at_end(client, ends)
            client.save_screenshot(str(out))
        except ViewerError:
            raise
        except (RuntimeError, ConnectionError, OSError, TimeoutError) as exc:
            if viewer is None:  # it could not be started: the system's own error
                raise
            first = str(exc).partition("\n")[0]
            why = re.sub(r"( \((os error \d+|Internal)\))+$", "", first).split(f"{out}: ", 1)
            if first.startswith("Failed to save screenshot to ") and len(why) == 2:  # a full disk
                raise OutputError(out, why[1]) from None
            reason = _viewer_failure(log_path) or first
            raise _needs_vulkan(f"the headless viewer could not render ({reason})") from None
        finally:  # the viewer is in a session of its own: a Ctrl-C does not reach it
            with held():
                if rec is not None:
                    rec.disconnect()
                if viewer is not None:
                    _stop(viewer)
    if not out.is_file():
        raise _needs_vulkan(f"the viewer did not write {out}")
    return out


def vulkan_available() -> bool:
    """Whether ``libvulkan`` and a driver manifest (in the standard folders or ``VK_DRIVER_FILES``
    / ``VK_ICD_FILENAMES``; Mesa's lavapipe counts) are installed, as ``--screenshot`` needs."""
    import ctypes.util

    if ctypes.util.find_library("vulkan") is None:
        return False
    listed = os.environ.get("VK_DRIVER_FILES") or os.environ.get("VK_ICD_FILENAMES")
    if listed:
        return any(Path(f).is_file() for f in listed.split(os.pathsep) if f)
    return any(glob.glob(os.path.join(d, "*.json")) for d in _ICD_DIRS)


def _wait_for_viewer(url: str, viewer: subprocess.Popen[bytes], log_path: Path) -> ViewerClient:
    """Wait until the viewer has drawn a frame, or fail with the reason it gave."""
    from rerun.experimental import ViewerClient

    deadline = time.monotonic() + _VIEWER_START_TIMEOUT_S
    client: ViewerClient | None = None
    while time.monotonic() < deadline:
        if viewer.poll() is not None:
            reason = _viewer_failure(log_path) or f"it exited with code {viewer.returncode}"
            raise _needs_vulkan(f"the headless viewer could not start ({reason})")
        try:
            client = client or ViewerClient.connect(url)  # ConnectionError at once if none listens
            client.take_screenshot(max_size=16)  # answers only once a frame has been drawn
            return client
        except (OSError, ConnectionError, RuntimeError):
            time.sleep(0.05)
    raise _needs_vulkan(f"the headless viewer did not start within {_VIEWER_START_TIMEOUT_S:g} s")


def _pause_at_end(client: ViewerClient, ends: dict[str, int]) -> None:
    """Wait until the viewer holds the whole recording (``ends``: :func:`stream`'s), then pause
    the time cursor at its end."""
    import numpy as np

    name = "time" if "time" in ends else next(iter(ends), None)
    deadline = time.monotonic() + LOAD_TIMEOUT_S
    while name is not None:
        state = client.get_state()
        timelines = state.recordings[0].timelines if state.recordings else []
        shown = next((t for t in timelines if t.name == name), None)
        end = ends[name]
        if not state.loading and shown is not None and (shown.end or -1) >= end:
            if shown.time_type == "sequence":
                client.set_time(name, sequence=end, play_state="paused")
            else:
                client.set_time(name, duration=np.timedelta64(end, "ns"), play_state="paused")
            break
        if time.monotonic() > deadline:
            raise TimeoutError(f"the recording did not load within {LOAD_TIMEOUT_S:g} s")
        time.sleep(0.05)
    time.sleep(0.8)  # frames for the plots to fit their axes and the start-up notices to fade


def _viewer_failure(log_path: Path) -> str | None:
    """The viewer's own one-line reason for failing, if its log has one."""
    try:
        text = log_path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    markers = ("No graphics adapter", "graphics adapter", "Vulkan", "panicked")
    return next((ln.strip()[:200] for m in markers for ln in text.splitlines() if m in ln), None)


def _stop(viewer: subprocess.Popen[bytes]) -> None:
    """Stop the viewer this command started: its session (the wrapper script and the binary)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(viewer.pid, sig)
        with contextlib.suppress(subprocess.TimeoutExpired):
            viewer.wait(5.0)
            return
