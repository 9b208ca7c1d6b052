"""Model files: one identified ARX model per motor (``theta`` = [c, d, a, b] per ``[motors.X]``,
other keys kept as ``stats``), as TOML, with provenance and the loop delay of the data; the keys
and versions are in docs/file-formats.md."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from cartctl.choices import find_file, is_number
from cartctl.data.outputs import writing
from cartctl.data.tomlfile import MODEL_FORMAT, check_format, read_loop_delay, read_toml, require
from cartctl.errors import CartctlError, DataFileError, InputError
from cartctl.model import ArxModel


@dataclass(frozen=True)
class Provenance:
    """Where a model came from: free-text ``source``, ISO 8601 ``created``, the ``data`` files
    fitted, the ``method`` ('arx', 'oe', 'report') and ``prefilter`` ('none' or a description)."""

    source: str
    created: str
    data: tuple[str, ...] = ()
    method: str = "arx"
    prefilter: str = "none"
    notes: str = ""

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self) | {"data": list(self.data)}
        return out if self.notes else {k: v for k, v in out.items() if k != "notes"}


@dataclass(frozen=True)
class ModelFile:
    """The motor models of one cart ('a' and/or 'b'), with provenance, each motor's extra
    figures as written (``stats``), the file read and the loop delay (ticks, None: unknown)."""

    motors: dict[str, ArxModel]
    provenance: Provenance
    stats: dict[str, dict[str, Any]] = field(default_factory=dict)
    path: Path | None = None
    loop_delay_ticks: int | None = None

    def motor(self, name: str) -> ArxModel:
        """The model of motor ``name``, with an error naming the motors present."""
        try:
            return self.motors[name]
        except KeyError:
            where = f" in {self.path}" if self.path else ""
            raise InputError(
                f"no model for motor '{name}'{where}; it has motor(s) {', '.join(self.motors)}"
            ) from None

    def __repr__(self) -> str:
        where = f" {self.path}" if self.path else ""
        ticks = self.loop_delay_ticks
        delay = "" if ticks is None else f", loop delay {ticks} tick{'s' * (ticks != 1)}"
        source = self.provenance.source
        source = source if len(source) <= 100 else source[:99] + "…"
        head = f"ModelFile{where}: Ts = {self.period_s:g} s{delay}, {self.provenance.method}"
        lines = [f"{head} ({source})"]
        for name, m in self.motors.items():
            theta = ", ".join(f"{v:.4g}" for v in m.theta)
            lines.append(f"  motor {name}: na = {m.na}, nb = {m.nb}, nk = {m.nk}, θ = [{theta}]")
        return "\n".join(lines)

    @property
    def period_s(self) -> float:
        return next(iter(self.motors.values())).period_s

    def to_toml_dict(self) -> dict[str, Any]:
        """The document written by :func:`save_models`."""
        motors: dict[str, dict[str, Any]] = {}
        for name, m in self.motors.items():
            motors[name] = {"theta": m.theta.tolist(), "na": m.na, "nb": m.nb, "nk": m.nk}
            motors[name] |= self.stats.get(name, {})
        doc: dict[str, Any] = {"format": MODEL_FORMAT, "period_s": self.period_s}
        if self.loop_delay_ticks is not None:
            doc["loop_delay_ticks"] = int(self.loop_delay_ticks)
        return doc | {"provenance": self.provenance.to_dict(), "motors": motors}


MAX_MODEL_ORDER = 50
"""The largest na, nb and nk a model file may hold (as identify fits; a design's state grows
with them)."""


def save_models(models: ModelFile, path: str | Path) -> Path:
    """Write a model file (TOML), creating parent folders; returns the path."""
    path = Path(path)
    header = "# cartctl motor models: theta = [a_1..a_na, b_0..b_nb-1], the report's [c, d, a, b]\n"
    with writing(path):
        path.write_text(header + tomli_w.dumps(models.to_toml_dict()), encoding="utf-8")
    return path


def load_models(path: str | Path) -> ModelFile:
    """Read a model file (a shipped one if the working folder has none)."""
    path = find_file(path)
    doc = read_toml(path, "model file")
    try:
        return _parse(doc, path)
    except DataFileError:
        raise
    except CartctlError as exc:
        raise DataFileError(path, str(exc)) from None


def _parse(doc: Mapping[str, Any], path: Path) -> ModelFile:
    if "format" in doc:  # a model file may leave it out
        check_format(doc, path, MODEL_FORMAT, "model file")
    period_s = float(require(doc, "period_s", (int, float), path, "the top level"))
    loop_delay = read_loop_delay(doc, path)
    prov = require(doc, "provenance", dict, path, "the top level") if "provenance" in doc else {}
    texts = dict.fromkeys(("source", "created", "method"), "unknown")  # what a file without says
    texts |= {"prefilter": "none", "notes": ""}
    texts = {k: str(prov.get(k, default)) for k, default in texts.items()}
    data = require(prov, "data", list, path, "[provenance]") if "data" in prov else ()
    provenance = Provenance(**texts, data=tuple(str(d) for d in data))
    motors_tab = require(doc, "motors", dict, path, "the top level")
    unknown = sorted(set(motors_tab) - {"a", "b"})
    if unknown:
        raise DataFileError(path, f"unknown motor(s) {unknown}; motors are 'a' and 'b'")
    if not motors_tab:
        raise DataFileError(path, "[motors] is empty; expected [motors.a] and/or [motors.b]")
    motors: dict[str, ArxModel] = {}
    stats: dict[str, dict[str, Any]] = {}
    for name in [m for m in ("a", "b") if m in motors_tab]:
        entry = motors_tab[name]
        where = f"[motors.{name}]"
        theta = require(entry, "theta", list, path, where)
        na, nb, nk = (require(entry, key, int, path, where) for key in ("na", "nb", "nk"))
        if not all(is_number(v) for v in theta):
            raise DataFileError(path, f"theta in {where} must be a list of numbers, got {theta!r}")
        if not all(math.isfinite(v) for v in theta):
            raise DataFileError(path, f"theta in {where} must hold finite numbers, got {theta!r}")
        for key, value, low in (("na", na, 0), ("nb", nb, 1), ("nk", nk, 0)):
            if not low <= value <= MAX_MODEL_ORDER:
                limits = f"{low}..{MAX_MODEL_ORDER} (as identify fits models)"
                raise DataFileError(path, f"{key} in {where} must be in {limits}, got {value}")
        motors[name] = ArxModel.from_theta(theta, na=na, nb=nb, nk=nk, period_s=period_s)
        stats[name] = {k: v for k, v in entry.items() if k not in ("theta", "na", "nb", "nk")}
    return ModelFile(motors, provenance, stats, path, loop_delay)
