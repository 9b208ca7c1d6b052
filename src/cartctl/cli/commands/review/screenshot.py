"""``cartctl review FILE.rrd --screenshot FILE.png``: the layout rendered by a headless viewer.

Starts ``rerun --headless`` in its own session, streams the recording into it, pauses the time
cursor at the end and saves the picture; then stops the viewer. Needs a Vulkan driver
(:func:`vulkan_available`); a failure is one :class:`~cartctl.cli.commands.review.viewer.ViewerError`
line naming the packages (:data:`VULKAN_HINT`).
"""

from __future__ import annotations

import glob
import os
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from cartctl.cli.commands.review.recording import (
    LOAD_TIMEOUT_S,
    Series,
    new_stream,
    read_recording,
    stream,
)
from cartctl.cli.commands.review.viewer import ViewerError, free_port, require_viewer
from cartctl.errors import InputError
from cartctl.sinks.rerun_problems import viewer_env

if TYPE_CHECKING:  # rerun takes ~0.6 s to import: only the review itself loads it
    from rerun.experimental import ViewerClient

VULKAN_HINT = "apt-get install mesa-vulkan-drivers libvulkan1"
SCREENSHOT_WINDOW = "1600x900"
"""Size of the headless viewer's window for ``--screenshot`` (logical points; the PNG may be
larger on a high-DPI scale)."""

_QUIET = ("--expect-data-soon", "--hide-welcome-screen")  # no welcome screen in the picture
_VIEWER_START_TIMEOUT_S = 20.0
_ICD_DIRS = (
    "/usr/share/vulkan/icd.d",
    "/usr/local/share/vulkan/icd.d",
    "/etc/vulkan/icd.d",
)


def screenshot(
    path: Path, out: Path, *, window: str = SCREENSHOT_WINDOW, extra: Series | None = None
) -> Path:
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
    extra : mapping, optional
        Series made from the recording (the smoothed speed), streamed after it.

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
    executable = require_viewer()
    out = out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    port = free_port()
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    with tempfile.TemporaryDirectory(prefix="cartctl-review-") as tmp:
        log_path = Path(tmp) / "viewer.log"
        with log_path.open("wb") as log:
            # Its own session, so the wrapper script and the viewer it starts stop together.
            viewer = subprocess.Popen(
                [executable, "--headless", "--port", str(port), "--window-size", window, *_QUIET],
                env={**viewer_env(), "RERUN_APP_ONLY": "true"},
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        rec = new_stream(entry)
        try:
            client = _wait_for_viewer(url, port, viewer, log_path)
            rec.connect_grpc(url)
            ends = stream(reader, entry, rec, extra=extra)
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
        The recording's last time per timeline (as
        :func:`~cartctl.cli.commands.review.recording.stream` returns).
    """
    import numpy as np

    name = "time" if "time" in ends else next(iter(ends), None)
    deadline = time.monotonic() + LOAD_TIMEOUT_S
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
            raise TimeoutError(f"the recording did not load within {LOAD_TIMEOUT_S:g} s")
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
