"""Controller files (TOML, docs/file-formats.md): what was asked, what came out, on which model,
for which loop delay, and when; loading checks that a file does not contradict itself. A
``[motors.X]`` entry holds the design's result itself (gains, estimator matrices), so the runtime
controllers built from it (:func:`build_controllers`) run exactly what was designed."""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from cartctl.cart import check_voltage_limit, encoder_quantum_rad_s
from cartctl.choices import find_file, is_number
from cartctl.data import tomlfile
from cartctl.data.outputs import writing
from cartctl.data.tomlfile import CONTROLLER_FORMAT, check_format, read_toml, require
from cartctl.design.controller_ss import (
    consistency_problems,
    controller_state_space,
    feedback_gains,
    kalman_from_entry,
)
from cartctl.design.request import METHODS, check_loop_delay
from cartctl.errors import CartctlError, DataFileError, InputError
from cartctl.runtime.base import Controller
from cartctl.runtime.kalman import KalmanDesign, KalmanSpeedEstimator, SteadyStateSpeedEstimator
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController

ONBOARD_LOOP_DELAY_TICKS = 1  # ticks: on board the cart, and in the simulated plants


def loop_site(loop_delay_ticks: int) -> str:
    """The file's ``plant_kind``: 'onboard' for at most one tick (the cart itself, the
    simulators), else 'serial' (the PC over the serial line)."""
    return "onboard" if loop_delay_ticks <= ONBOARD_LOOP_DELAY_TICKS else "serial"


def common_loop_delay(nk: Mapping[str, int], extra_delay_ticks: int) -> int:
    """The one loop delay, nk − 1 + extra, of motors with input delays ``nk`` (motor → nk);
    ValueError when they differ (a controller file is for one loop)."""
    if len(set(nk.values())) > 1:
        shown = ", ".join(f"motor {m}: nk = {n}" for m, n in sorted(nk.items()))
        raise ValueError(
            f"the motors' models have different input delays ({shown}), so one file cannot be "
            "for one loop; identify with one --delay for both or design each motor on its own"
        )
    return check_loop_delay(None, next(iter(nk.values())), extra_delay_ticks)


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes: ties a controller to the exact model it was designed on."""
    return hashlib.sha256(find_file(path).read_bytes()).hexdigest()


def _plain(value: Any) -> Any:
    """numpy arrays and scalars → lists and floats, None dropped (TOML has no null)."""
    if isinstance(value, np.ndarray | np.generic):  # a numpy scalar's tolist() is its item()
        return _plain(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _short(value: Any) -> str:  # 4 significant figures
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_short(v) for v in value) + "]"
    return f"{value:.4g}" if isinstance(value, float | int) else str(value)


@dataclass(frozen=True)
class ControllerFile:
    """A designed controller for both motors (the keys of a controller file). ``model_path``
    opens from the working directory (the file stores it relative to its own folder); ``ignored``
    holds the self-contradictions a ``force=True`` load let through."""

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
    loop_delay_ticks: int | None = None
    ignored: tuple[str, ...] = field(default=(), compare=False)

    def __repr__(self) -> str:
        """What, for which loop, each motor's gains (not the estimator's matrices)."""
        where = f" {self.path}" if self.path else ""
        ticks = self.loop_delay_ticks
        delay = "" if ticks is None else f", loop delay {ticks} tick{'s' * (ticks != 1)}"
        lines = [f"ControllerFile{where}: {self.method}, Ts = {self.period_s:g} s{delay}, "
                 f"limit {self.voltage_limit_v:g} V, on {self.model_path}"]  # fmt: skip
        for name, entry in self.motors.items():
            gains = [f"{k} {_short(entry[k])}" for k in ("kp", "ki", "K", "Ki", "Kr") if k in entry]
            figures = entry.get("analysis", {})
            margins = [f"{label} {figures[k]:.3g}{unit}" for k, label, unit in (
                ("phase_margin_deg", "phase margin", "°"), ("gain_margin_db", "gain margin", " dB"))
                if isinstance(figures.get(k), float)]  # fmt: skip
            lines.append(f"  motor {name}: " + ", ".join(gains + margins))
        return "\n".join(lines)

    @property
    def loop_site(self) -> str | None:
        """:func:`loop_site` of the loop delay, None without one."""
        return None if self.loop_delay_ticks is None else loop_site(self.loop_delay_ticks)

    def to_toml_dict(self, folder: str | Path | None = None) -> dict[str, Any]:
        """The document :func:`save_controller` writes, the model path relative to ``folder``."""
        model_path = self.model_path if folder is None else _relative_to(self.model_path, folder)
        return _plain(
            {
                "format": CONTROLLER_FORMAT,
                "method": self.method,
                "period_s": self.period_s,
                "voltage_limit_v": self.voltage_limit_v,
                "loop_delay_ticks": self.loop_delay_ticks,  # both dropped when None
                "plant_kind": self.loop_site,
                "created": self.created,
                "command": self.command,
                "model": {"path": model_path, "sha256": self.model_sha256},
                "request": self.request,
                "motors": self.motors,
            }
        )

    def model_changed(self) -> bool:
        """True when the model file now differs from the one designed on (or is gone)."""
        path = find_file(self.model_path)
        return not path.is_file() or file_sha256(path) != self.model_sha256


def reaction_gain(method: str, entry: Mapping[str, Any], period_s: float) -> float:
    """The voltage step (V per rad/s) one motor's controller makes in the tick a change of the
    measured speed arrives (its feedthrough from y to u; K·L for a state feedback, whose entries
    of K weigh estimator states); NaN when the entry cannot be built (the builder names why)."""
    try:
        return abs(float(controller_state_space(method, entry, period_s).D[0, 1]))
    except (KeyError, TypeError, ValueError, np.linalg.LinAlgError):
        return math.nan


def absurd_gain(controller: ControllerFile) -> str | None:
    """The first gain that is no controller but a switch, or None: a proportional gain (``kp``,
    ``Kr``) that puts the whole voltage limit on one encoder count per tick, an integral gain
    (``ki``) that does so in one tick, a state feedback whose :func:`reaction_gain` does so, or
    not a finite number."""
    limit = controller.voltage_limit_v
    q = encoder_quantum_rad_s(controller.period_s)
    for motor, entry in controller.motors.items():
        gains = (("kp", q), ("Kr", q), ("ki", q * controller.period_s), ("K", 0.0))
        for key, per_error in gains:  # K: only finite here, its switch test follows
            values = entry.get(key, [])
            for value in values if isinstance(values, list) else [values]:
                if not is_number(value):
                    continue  # build_controllers names a gain that is not a number
                if not math.isfinite(value):
                    return f"[motors.{motor}] {key} = {value} is not a finite number"
                if abs(value) * per_error >= limit:
                    unit = "V/rad" if key == "ki" else "V per rad/s"
                    return (
                        f"[motors.{motor}] {key} = {value:g} {unit} puts the whole {limit:g} V on "
                        f"an error of one encoder count ({q:.3g} rad/s"
                        f"{' for one tick' if key == 'ki' else ''}): that is a switch, not a "
                        f"controller; keep |{key}| below {limit / per_error:.3g}"
                    )
        gain = reaction_gain(controller.method, entry, controller.period_s) if "K" in entry else 0
        if gain * q >= limit:
            return (
                f"[motors.{motor}] K with the estimator's L answers one encoder count "
                f"({q:.3g} rad/s) with {gain * q:.3g} V in the tick it arrives, the whole "
                f"{limit:g} V or more: that is a switch, not a controller; keep |K·L| below "
                f"{limit / q:.3g} V per rad/s"
            )
    return None


def _relative_to(model_path: str, folder: str | Path) -> str:
    """``model_path`` from ``folder``, POSIX separators; a shipped model without a local copy
    keeps its shipped name."""
    if not Path(model_path).exists() and find_file(model_path) != Path(model_path):
        return Path(model_path).as_posix()
    try:
        relative = os.path.relpath(os.path.abspath(model_path), os.path.abspath(folder))
    except ValueError:  # another drive (Windows): only an absolute path works
        return Path(os.path.abspath(model_path)).as_posix()
    return Path(relative).as_posix()


def _resolve_model(stored: str, controller_path: Path, *, legacy: bool) -> str:
    """The stored ``[model] path`` from the working directory (relative to the controller's
    folder; an older, ``legacy`` file's to the design's working directory)."""
    if Path(stored).is_absolute():
        return stored
    resolved = os.path.normpath(os.path.join(controller_path.parent, stored))
    if legacy and not Path(resolved).is_file() and Path(stored).is_file():
        return stored
    if not Path(resolved).is_file() and find_file(stored).is_file():
        return str(find_file(stored))  # a shipped model's name (_relative_to)
    return resolved


def save_controller(controller: ControllerFile, path: str | Path) -> Path:
    """Write a controller file (parent folders created, the model path relative to its folder)."""
    path = Path(path)
    header = f"# cartctl controller ({controller.method}); regenerate with: {controller.command}\n"
    document = controller.to_toml_dict(path.parent)
    with writing(path):
        path.write_text(header + tomli_w.dumps(document), encoding="utf-8")
    return path


def _derived_loop_delay(
    path: Path, model_path: str, request: Mapping[str, Any], motors: Mapping[str, Any]
) -> int:
    """The loop delay of a file without ``loop_delay_ticks``: its model's nk − 1 + extra delay."""
    from cartctl.data.modelfile import load_models

    extra = request.get("extra_delay_ticks", 0)
    if not isinstance(extra, int) or isinstance(extra, bool) or extra < 0:
        raise DataFileError(
            path, f"request.extra_delay_ticks must be a whole number >= 0, got {extra!r}"
        )
    try:
        models = load_models(model_path)
        nk = {m: models.motor(m).nk for m in motors}
        return common_loop_delay(nk, extra)
    except (CartctlError, ValueError) as exc:
        raise DataFileError(
            path,
            f"has no loop_delay_ticks (a file from an older cartctl) and it cannot be derived from "
            f"its model {model_path} ({exc}); redesign it with the command in its header, or add "
            "loop_delay_ticks = N (the model's nk − 1 + extra delay)",
        ) from None


def check_period(where: str | Path, file_period_s: float, period_s: float) -> None:
    """Refuse a controller designed for Ts = ``file_period_s`` on a plant ticking every
    ``period_s`` (s), naming ``where`` (its file, or what the caller calls it)."""
    if abs(file_period_s - period_s) > 1e-9:
        raise DataFileError(
            where,
            f"is designed for Ts = {file_period_s:g} s but the plant ticks every {period_s:g} s; "
            "design it on a model of the plant's period",
        )


def load_controller(
    path: str | Path, *, force: bool = False, period_s: float | None = None
) -> ControllerFile:
    """Read a controller file, with one clear error (MissingFileError, DataFileError) for each
    way it can be wrong. ``force`` loads a file whose ``controller_num``/``controller_den``
    disagree with its gains anyway (the gains are what runs; the disagreements go to
    ``ignored``); ``period_s``, the plant's tick (s), refuses a file for another period.
    """
    path = find_file(path)  # the working folder's, else the shipped one
    doc = read_toml(path, "controller file")
    check_format(doc, path, CONTROLLER_FORMAT, "controller file")
    file_period_s = float(require(doc, "period_s", (int, float), path, "the top level"))
    if period_s is not None:
        check_period(path, file_period_s, period_s)
    method = require(doc, "method", str, path, "the top level")
    if method not in METHODS:
        raise DataFileError(path, f"unknown method {method!r}; expected one of {', '.join(METHODS)}")  # fmt: skip
    model = require(doc, "model", dict, path, "the top level")
    motors = require(doc, "motors", dict, path, "the top level")
    if not motors or set(motors) - {"a", "b"}:
        raise DataFileError(path, f"[motors] must hold 'a' and/or 'b', got {sorted(motors)}")
    limit = require(doc, "voltage_limit_v", (int, float), path, "the top level")
    try:
        limit = check_voltage_limit(limit, "voltage_limit_v")
    except InputError as exc:
        raise DataFileError(path, str(exc)) from None
    legacy = "loop_delay_ticks" not in doc
    model_path = _resolve_model(
        str(require(model, "path", str, path, "[model]")), path, legacy=legacy
    )
    request = dict(doc.get("request", {}))
    delay = tomlfile.read_loop_delay(doc, path)
    if delay is None:  # a file from an older cartctl
        delay = _derived_loop_delay(path, model_path, request, motors)
    site = doc.get("plant_kind", loop_site(delay))
    if site != loop_site(delay):
        raise DataFileError(
            path,
            f"plant_kind = {site!r} contradicts loop_delay_ticks = {delay} ('onboard' is a loop "
            f"delay of {ONBOARD_LOOP_DELAY_TICKS} tick, 'serial' more)",
        )
    if not (math.isfinite(file_period_s) and 0.0 < file_period_s <= 1.0):
        raise DataFileError(path, f"period_s must be in (0, 1] s, got {file_period_s}")
    controller = ControllerFile(
        method=method,
        period_s=file_period_s,
        voltage_limit_v=limit,
        model_path=model_path,
        model_sha256=str(require(model, "sha256", str, path, "[model]")),
        request=request,
        motors={m: dict(v) for m, v in motors.items()},
        created=str(doc.get("created", "unknown")),
        command=str(doc.get("command", "")),
        path=path,
        loop_delay_ticks=delay,
    )
    problem = absurd_gain(controller)
    if problem is not None:
        raise DataFileError(path, problem)
    problems = consistency_problems(controller)
    if problems and not force:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise DataFileError(path, problems[0] + more)
    return replace(controller, ignored=tuple(problems))


def make_estimator(design: KalmanDesign) -> KalmanSpeedEstimator | SteadyStateSpeedEstimator:
    """The runtime estimator of a design: the fixed steady-state gain L (a design's P is
    stationary), or, with timing noise, the filter whose gain moves at every command change. A
    file's ``estimator_gain`` key (older versions) is ignored."""
    if design.timing_noise_std_ticks > 0.0:
        return KalmanSpeedEstimator(design)
    return SteadyStateSpeedEstimator(design)


def build_controller(
    method: str, entry: Mapping[str, Any], period_s: float, voltage_limit_v: float
) -> Controller:
    """One motor's runtime controller from its ``[motors.X]`` entry; KeyError, TypeError or
    ValueError for a key missing or not fitting."""
    if method == "pi":
        est = entry.get("estimator")
        try:
            kp, ki = float(entry["kp"]), float(entry["ki"])
        except (TypeError, ValueError):
            raise ValueError("kp and ki must be numbers") from None
        return PiController(
            kp,
            ki,
            period_s,
            voltage_limit_v=voltage_limit_v,
            anti_windup=str(entry.get("anti_windup", "conditional")),
            estimator=None if est is None else make_estimator(kalman_from_entry(est)),
        )
    gains = feedback_gains(entry, period_s)
    estimator = make_estimator(gains.estimator)
    return StateFeedbackController(gains, estimator=estimator, voltage_limit_v=voltage_limit_v)


def build_controllers(
    controller: ControllerFile, *, voltage_limit_v: float | None = None
) -> dict[str, Controller]:
    """The runtime controller of each motor in a controller file, limited to ``voltage_limit_v``
    (V; at most, and by default, the file's): DataFileError for a motor entry that misses a key
    or holds inconsistent numbers, InputError for a limit above the file's."""
    limit = controller.voltage_limit_v
    if voltage_limit_v is not None:  # at most the file's limit
        limit = check_voltage_limit(voltage_limit_v, most_v=limit)
    out: dict[str, Controller] = {}
    for motor, entry in controller.motors.items():
        try:
            out[motor] = build_controller(controller.method, entry, controller.period_s, limit)
        except (KeyError, TypeError, ValueError) as exc:
            why = f" misses {exc.args[0]}" if isinstance(exc, KeyError) else f": {exc}"
            raise DataFileError(
                controller.path or "controller file", f"[motors.{motor}]{why}"
            ) from None
    return out
