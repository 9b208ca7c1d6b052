"""Controller files (TOML): what was asked, what came out, on which model, and when.

``cartctl design --out`` writes them into ``controllers/``; the 10 ms loop loads them. A file::

    format = "cartctl-controller/1"
    method = "pi"                      # or "poles"
    period_s = 0.01
    voltage_limit_v = 12.0
    created = "2026-11-22T15:00:00+00:00"
    command = "cartctl design models/ground.toml --method pi ..."

    [model]                            # the model it was designed on
    path = "models/ground.toml"
    sha256 = "…"                       # of the model file's bytes

    [request]                          # the user's specification (method-specific)
    phase_margin_deg = 60.0

    [motors.a]                         # the result: gains, estimator matrices, analysis
    kp = 0.5
    ki = 12.0

Loading checks the format and the keys; :mod:`cartctl.design.build` turns a file into runtime
controllers.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from cartctl.errors import DataFileError
from cartctl.tomlfile import read_toml, require

FORMAT = "cartctl-controller/1"
METHODS = ("pi", "poles")


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes (hex), to tie a controller to the exact model it was designed on."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _plain(value: Any) -> Any:
    """numpy arrays and scalars → lists and floats, None dropped by the caller (TOML has no null)."""
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


@dataclass(frozen=True)
class ControllerFile:
    """A designed controller for both motors.

    Attributes
    ----------
    method : {'pi', 'poles'}
    period_s : float
        Tick period the design assumes (s).
    voltage_limit_v : float
        Command saturation (V), at most 12.
    model_path : str
        The model file designed on.
    model_sha256 : str
        Its content hash at design time.
    request : dict
        The specification (method-specific keys).
    motors : dict of str to dict
        Per motor: gains, estimator matrices, analysis figures.
    created : str
        ISO 8601 date-time.
    command : str
        The command line that made it (to regenerate it).
    path : Path or None
        Where it was read from.
    """

    method: str
    period_s: float
    voltage_limit_v: float
    model_path: str
    model_sha256: str
    request: dict[str, Any]
    motors: dict[str, dict[str, Any]]
    created: str
    command: str = ""
    path: Path | None = field(default=None, compare=False)

    def to_toml_dict(self) -> dict[str, Any]:
        """The document :func:`save_controller` writes."""
        return _plain(
            {
                "format": FORMAT,
                "method": self.method,
                "period_s": self.period_s,
                "voltage_limit_v": self.voltage_limit_v,
                "created": self.created,
                "command": self.command,
                "model": {"path": self.model_path, "sha256": self.model_sha256},
                "request": self.request,
                "motors": self.motors,
            }
        )

    def model_changed(self) -> bool:
        """True when the model file now differs from the one designed on (or is gone)."""
        path = Path(self.model_path)
        return not path.is_file() or file_sha256(path) != self.model_sha256


def save_controller(controller: ControllerFile, path: str | Path) -> Path:
    """Write a controller file, creating parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = f"# cartctl controller ({controller.method}); regenerate with: {controller.command}\n"
    path.write_text(header + tomli_w.dumps(controller.to_toml_dict()), encoding="utf-8")
    return path


def load_controller(path: str | Path) -> ControllerFile:
    """Read a controller file; clear errors for a missing file, bad TOML or missing keys."""
    path = Path(path)
    doc = read_toml(path, "controller file")
    if doc.get("format") != FORMAT:
        raise DataFileError(path, f"unknown format {doc.get('format')!r}; expected {FORMAT!r}")
    method = require(doc, "method", str, path, "the top level")
    if method not in METHODS:
        raise DataFileError(
            path, f"unknown method {method!r}; expected one of {', '.join(METHODS)}"
        )
    model = require(doc, "model", dict, path, "the top level")
    motors = require(doc, "motors", dict, path, "the top level")
    if not motors or set(motors) - {"a", "b"}:
        raise DataFileError(path, f"[motors] must hold 'a' and/or 'b', got {sorted(motors)}")
    limit = float(require(doc, "voltage_limit_v", (int, float), path, "the top level"))
    if not 0.0 < limit <= 12.0:
        raise DataFileError(path, f"voltage_limit_v must be in (0, 12] V, got {limit}")
    return ControllerFile(
        method=method,
        period_s=float(require(doc, "period_s", (int, float), path, "the top level")),
        voltage_limit_v=limit,
        model_path=str(require(model, "path", str, path, "[model]")),
        model_sha256=str(require(model, "sha256", str, path, "[model]")),
        request=dict(doc.get("request", {})),
        motors={m: dict(v) for m, v in motors.items()},
        created=str(doc.get("created", "unknown")),
        command=str(doc.get("command", "")),
        path=path,
    )
