"""The loop a trace was recorded in: its *meta* file, ``logs/ground.csv`` → ``logs/ground.meta.toml``.

``excite`` and ``run`` write it; ``identify`` carries its loop delay (ticks from a measurement to
the voltage it leads to on the motor) into the model file. A trace without one has an unknown
loop delay. The keys are in docs/file-formats.md.
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


@dataclass(frozen=True)
class TraceMeta:
    """What a trace's meta file says ('' where not known; ``controller`` and ``model`` are a
    run's files as absolute paths, what a smoother of the trace needs)."""

    plant: str
    loop_delay_ticks: int | None
    command: str = ""
    controller: str = ""
    model: str = ""
    created: str = ""
    path: Path | None = None

    def to_toml_dict(self) -> dict[str, Any]:
        """The document :func:`write_trace_meta` writes (no key for an unknown loop delay)."""
        out: dict[str, Any] = {"format": TRACE_META_FORMAT, "plant": self.plant}
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
    return path.with_name(path.stem + ".meta.toml")


def write_trace_meta(
    trace_path: str | Path,
    *,
    plant: str,
    loop_delay_ticks: int | None,
    command: str = "",
    controller: str | Path | None = None,
    model: str | Path | None = None,
) -> Path:
    """Write the meta file beside the trace ``trace_path`` (which need not exist yet)."""
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
    """The meta file of the trace ``trace_path``, or None when it has none."""
    path = meta_path(trace_path)
    if not path.is_file():
        return None
    doc = read_toml(path, "trace meta file")
    fmt = doc.get("format", TRACE_META_FORMAT)
    if fmt != TRACE_META_FORMAT:
        raise DataFileError(path, f"unknown format {fmt!r}; expected {TRACE_META_FORMAT!r}")
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
    """The one loop delay of the traces that know theirs (None if none does); InputError when
    two differ, as one model is for one loop."""
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
    """The loop delay the traces were recorded in, from their meta files (:func:`agreed_loop_delay`)."""
    return agreed_loop_delay({str(p): read_trace_meta(p) for p in trace_paths})
