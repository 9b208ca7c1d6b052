"""``cartctl review FILE.rrd [--web]``: a recording in the native Rerun viewer or the web viewer.

Also the pieces the headless screenshot shares: :class:`ViewerError`, the viewer executable
(:func:`require_viewer`) and a free local port (:func:`free_port`).
"""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from urllib.parse import quote

from cartctl.cli.commands.review.recording import (
    Series,
    new_stream,
    read_recording,
    stream,
)
from cartctl.errors import CartctlError


class ViewerError(CartctlError, RuntimeError):
    """The viewer could not be started, or could not render."""


def require_viewer() -> str:
    """The Rerun viewer executable.

    Raises
    ------
    ViewerError
        None next to Python or on PATH.
    """
    from cartctl.sinks.viewer import viewer_executable

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
    """Stream the recording and the layout into the native viewer (spawned if none is running).

    ``extra``: series made from the recording (the smoothed speed), streamed after it.

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
    executable = require_viewer()
    url = f"rerun+http://127.0.0.1:{VIEWER_PORT}/proxy"
    rec = new_stream(entry)
    try:
        # Connects to a viewer already listening on the port instead of starting a second one.
        rr.spawn(port=VIEWER_PORT, connect=False, executable_path=executable, recording=rec)
        if not viewer_reachable(url):
            raise ViewerError(f"the viewer ({executable}) did not start on this display")
        rec.connect_grpc(url)
        stream(reader, entry, rec, extra=extra)
    except ViewerError:
        raise
    except (RuntimeError, ConnectionError, OSError) as exc:
        raise ViewerError(f"could not hand the recording to the viewer at {url}: {exc}") from None
    finally:
        rec.disconnect()
    return url


def serve_web(
    path: Path, *, wait: Callable[[str], None] | None = None, extra: Series | None = None
) -> str:
    """Serve the recording and the layout to the web viewer, print its URL, and block.

    Parameters
    ----------
    path : Path
        The ``.rrd`` file.
    wait : callable, optional
        Called with the URL while serving; returning stops the servers. Default: until Ctrl-C.
    extra : mapping, optional
        Series made from the recording (the smoothed speed), streamed after it.

    Returns
    -------
    str
        The web viewer's URL.
    """
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
