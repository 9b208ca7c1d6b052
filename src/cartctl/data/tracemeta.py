"""The loop a trace was recorded in: a small TOML file beside the trace (its *meta* file).

The CSV's columns are fixed (docs/architecture.md), so what the trace cannot say about itself
goes beside it:
``logs/ground.csv`` has ``logs/ground.meta.toml``::

    format = "cartctl-trace-meta/1"
    plant = "physics (preset ground)"
    loop_delay_ticks = 1          # measurement to applied voltage; absent when unknown
    command = "cartctl excite --plant physics ..."
    created = "2026-11-25T23:40:00+00:00"

``cartctl excite`` and ``cartctl run`` write it; ``cartctl identify`` reads those of its data files
and carries the loop delay into the model file, so ``design`` designs for the loop the data came
from. A trace without a meta file (a QRoboticsCenter log, a file from an older cartctl) still reads;
its loop delay is unknown.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import tomli_w

from cartctl.data.tomlfile import TRACE_META_FORMAT, read_toml, require
from cartctl.errors import DataFileError, InputError

FORMAT = TRACE_META_FORMAT
SUFFIX = ".meta.toml"


@dataclass(frozen=True)
class TraceMeta:
    """What a trace's meta file says.

    Attributes
    ----------
    plant : str
        The plant it was recorded on, as the command described it ('physics (preset ground)').
    loop_delay_ticks : int or None
        Ticks from a measurement to the voltage it leads to being on the motor: the echo delay
        measured over serial, the known 1 of the simulators; None when unknown.
    command : str
        The command that recorded it ('' when not known).
    controller, model : str
        A closed-loop run's controller file and the model it was designed on (absolute paths;
        '' for an excitation or when not known): what a smoother of the trace needs.
    created : str
        ISO 8601 date-time of the recording ('' when not known).
    path : Path or None
        The meta file it was read from.
    """

    plant: str
    loop_delay_ticks: int | None
    command: str = ""
    controller: str = ""
    model: str = ""
    created: str = ""
    path: Path | None = None

    def to_toml_dict(self) -> dict[str, Any]:
        """The document :func:`write_trace_meta` writes (no key for an unknown loop delay)."""
        out: dict[str, Any] = {"format": FORMAT, "plant": self.plant}
        if self.loop_delay_ticks is not None:
            out["loop_delay_ticks"] = int(self.loop_delay_ticks)
        if self.command:
            out["command"] = self.command
        for key in ("controller", "model"):
            if getattr(self, key):
                out[key] = getattr(self, key)
        out["created"] = self.created or datetime.now(UTC).isoformat(timespec="seconds")
        return out


def meta_path(trace_path: str | Path) -> Path:
    """The meta file of a trace: ``logs/ground.csv`` → ``logs/ground.meta.toml``."""
    path = Path(trace_path)
    return path.with_name(path.stem + SUFFIX)


def write_trace_meta(
    trace_path: str | Path,
    *,
    plant: str,
    loop_delay_ticks: int | None,
    command: str = "",
    controller: str | Path | None = None,
    model: str | Path | None = None,
) -> Path:
    """Write the meta file beside the trace ``trace_path``; returns the meta file's path.

    Parameters
    ----------
    trace_path : str or Path
        The trace (CSV) the meta file describes; it need not exist yet.
    plant : str
        The plant's description.
    loop_delay_ticks : int or None
        The loop delay (ticks), None when unknown (the key is then left out).
    command : str
        The command that recorded the trace.
    controller, model : str or Path, optional
        A run's controller file and its design model (stored as absolute paths).
    """
    if loop_delay_ticks is not None and int(loop_delay_ticks) < 0:
        raise InputError(f"loop_delay_ticks must be >= 0 ticks, got {loop_delay_ticks}")
    meta = TraceMeta(
        plant=plant,
        loop_delay_ticks=loop_delay_ticks,
        command=command,
        controller="" if controller is None else str(Path(controller).resolve()),
        model="" if model is None else str(Path(model).resolve()),
    )
    path = meta_path(trace_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        "# cartctl: the loop the trace beside this file was recorded in\n"
        + tomli_w.dumps(meta.to_toml_dict()),
        encoding="utf-8",
    )
    return path


def read_trace_meta(trace_path: str | Path) -> TraceMeta | None:
    """The meta file of the trace ``trace_path``, or None when it has none.

    Raises
    ------
    DataFileError
        The meta file exists but is not valid TOML, has another format, or a bad key.
    """
    path = meta_path(trace_path)
    if not path.is_file():
        return None
    doc = read_toml(path, "trace meta file")
    fmt = doc.get("format", FORMAT)
    if fmt != FORMAT:
        raise DataFileError(path, f"unknown format {fmt!r}; expected {FORMAT!r}")
    delay = None
    if "loop_delay_ticks" in doc:
        delay = require(doc, "loop_delay_ticks", int, path, "the top level")
        if delay < 0:
            raise DataFileError(path, f"loop_delay_ticks must be >= 0 ticks, got {delay}")
    return TraceMeta(
        plant=str(doc.get("plant", "unknown")),
        loop_delay_ticks=delay,
        command=str(doc.get("command", "")),
        controller=str(doc.get("controller", "")),
        model=str(doc.get("model", "")),
        created=str(doc.get("created", "")),
        path=path,
    )


def agreed_loop_delay(metas: Mapping[str, TraceMeta | None]) -> int | None:
    """The one loop delay of several traces (trace path → its meta, None without one).

    Traces without a meta file, or whose loop delay is unknown, do not take part. Returns None
    when no trace knows its loop delay.

    Raises
    ------
    InputError
        Two traces were recorded in loops with different delays: one model is for one loop.
    """
    known = {
        p: m.loop_delay_ticks for p, m in metas.items() if m and m.loop_delay_ticks is not None
    }
    if len(set(known.values())) > 1:
        shown = ", ".join(f"{p}: {d}" for p, d in known.items())
        raise InputError(
            f"the traces were recorded in loops with different delays ({shown} tick(s), from "
            "their .meta.toml files); identify the data of one loop at a time"
        )
    return next(iter(known.values()), None)


def loop_delay_of(trace_paths: Sequence[str | Path]) -> int | None:
    """The loop delay the traces ``trace_paths`` were recorded in, from their meta files.

    None when none of them has one that knows it; InputError when they disagree
    (:func:`agreed_loop_delay`), DataFileError for a broken meta file.
    """
    return agreed_loop_delay({str(p): read_trace_meta(p) for p in trace_paths})
