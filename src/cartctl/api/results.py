"""The results the Python API returns: identified models, designs and simulated runs.

Each prints as a title, one table row per motor and a line of hints, and shows as the same table
in Jupyter; the arrays and full results stay in their attributes. matplotlib is imported only
when a figure is drawn."""

from __future__ import annotations

import html
import math
import shlex
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cartctl.data.modelfile import ModelFile, save_models
from cartctl.data.outputs import check_output_file
from cartctl.data.trace import MOTORS
from cartctl.design.controllerfile import ControllerFile, save_controller
from cartctl.design.make import Designs, controller_file
from cartctl.design.request import DesignRequest
from cartctl.errors import InputError
from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, MotorIdentification
from cartctl.identification.pipeline import model_file as identified_model_file
from cartctl.measures.numfmt import MISSING, render_table
from cartctl.model import ArxModel

__all__ = ["Design", "Identification", "MotorResult", "SimulationResult"]


def number(value: float | None, digits: int = 4) -> str:
    """``value`` with ``digits`` significant figures; a dash for None or NaN."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return MISSING
    text = f"{float(value):.{digits}g}"
    return "0" if text == "-0" else text


def numbers(values: Iterable[float], digits: int = 4) -> str:
    """A short list ``[-0.9157, 0.2044, …]`` of ``values`` with ``digits`` significant figures."""
    return "[" + ", ".join(number(v, digits) for v in values) + "]"


def _has(motors: Collection[str], motor: str, what: str) -> str:
    """``motor`` if a result of ``motors`` has it; else InputError (not a bare KeyError)."""
    if motor not in motors:
        raise InputError(f"no motor {motor!r} in this {what}; it has motor(s) {', '.join(motors)}")
    return motor


_IDENT_HEADERS = ("motor", "nk", "θ", "θ std", "fit sim (%)", "fit pred (%)", "max |pole|")


_Table = tuple[str, Sequence[str], Sequence[Sequence[str]], str]  # title, headers, rows, hint


class _Shown:
    """``repr()`` and Jupyter's display of a result in a few lines, from the class's
    ``_summary()``: a title, a table (one row per motor, cells formatted, units in the headers)
    and a line of hints (what else the object offers)."""

    def _summary(self) -> _Table:
        raise NotImplementedError

    def __repr__(self) -> str:
        title, headers, rows, hint = self._summary()
        return "\n".join([title, *render_table(headers, rows, indent="  "), "  " + hint])

    def _repr_html_(self) -> str:
        title, headers, rows, hint = self._summary()

        def cells(tag: str, values: Iterable[str]) -> str:
            return "".join(f"<{tag}>{html.escape(v)}</{tag}>" for v in values)

        body = "".join(f"<tr>{cells('td', row)}</tr>" for row in rows)
        return (
            f"<div><strong>{html.escape(title)}</strong><table><thead><tr>{cells('th', headers)}"
            f"</tr></thead><tbody>{body}</tbody></table><br><small>{html.escape(hint)}</small></div>"
        )


@dataclass(frozen=True, repr=False, eq=False)
class MotorResult(_Shown):
    """One motor's identified model.

    Attributes
    ----------
    theta, theta_std : ndarray
        The report's θ = [c, d, a, b] (for na = nb = 2) and its standard deviations.
    tf : control.TransferFunction
        The model as python-control's discrete transfer function (dt = Ts).
    details : MotorIdentification
        Everything ``identify`` computed (ARX, OE, the delay estimate…).
    """

    model: ArxModel
    theta: NDArray[np.float64]
    theta_std: NDArray[np.float64]
    fit_simulation_percent: float
    fit_prediction_percent: float
    tf: Any
    details: MotorIdentification

    def row(self, motor: str) -> tuple[str, ...]:
        return (motor, str(self.model.nk), numbers(self.theta), numbers(self.theta_std, 2),
                number(self.fit_simulation_percent), number(self.fit_prediction_percent),
                number(self.model.pole_radius()))  # fmt: skip

    def _summary(self) -> _Table:
        m = self.model
        title = (f"MotorResult: {self.details.chosen.method.upper()} model of motor "
                 f"{self.details.motor}, na = {len(m.ar)}, nb = {len(m.b)}, "
                 f"Ts = {number(m.period_s)} s")  # fmt: skip
        hint = ".model, .tf (python-control), .theta, .details"
        return title, _IDENT_HEADERS, (self.row(self.details.motor),), hint


@dataclass(frozen=True, repr=False, eq=False)
class Identification(_Shown):
    """Per-motor results of :func:`~cartctl.api.identify` (``result["a"]``), saveable as a model
    file."""

    motors: dict[str, MotorResult]
    result: IdentifyResult
    request: IdentifyRequest
    sources: tuple[str, ...]

    def __getitem__(self, motor: str) -> MotorResult:
        return self.motors[_has(self.motors, motor, "identification")]

    def model_file(self) -> ModelFile:
        """The models with their provenance, as ``identify --out`` writes them."""
        return identified_model_file(
            self.result, list(self.sources), self.request, source="cartctl.identify()"
        )

    def save(self, path: str | Path) -> Path:
        """Write the model file; returns its path."""
        save_models(self.model_file(), check_output_file(path, "save"))
        return Path(path)

    def _summary(self) -> _Table:
        r = self.request
        shown = ", ".join(self.sources[:2]) + (f" and {len(self.sources) - 2} more"
                                               if len(self.sources) > 2 else "")  # fmt: skip
        prefilter = "" if r.prefilter is None else f", prefilter {number(r.prefilter.cutoff_hz)} Hz"
        period = next(iter(self.motors.values())).model.period_s if self.motors else None
        ticks = self.result.loop_delay_ticks
        loop = "" if ticks is None else f", loop delay {ticks} tick{'s' * (ticks != 1)}"
        title = (f"Identification: {r.method.upper()}, na = {r.na}, nb = {r.nb}{prefilter}, "
                 f"Ts = {number(period)} s{loop}, from {shown}")  # fmt: skip
        rows = tuple(result.row(m) for m, result in self.motors.items())
        hint = f"ident[{min(self.motors)!r}] for one motor (.tf, .model); .save('models/mine.toml')"
        return title, _IDENT_HEADERS, rows, hint


_DESIGN_COLUMNS = {  # a figure of a motor's entry or of its simulated step: its header
    "phase_margin_deg": "phase margin (°)",
    "gain_margin_db": "gain margin (dB)",
    "crossover_hz": "crossover (Hz)",
    "overshoot_percent": "overshoot (%)",
    "settling_time_s": "settling (s)",
}


def _gains(entry: dict[str, Any]) -> str:
    if "kp" in entry:
        return f"kp {number(entry['kp'])}, ki {number(entry['ki'])}"
    return f"K {numbers(entry.get('K', ()), 3)}, Kr {number(entry.get('Kr'))}"


@dataclass(frozen=True, repr=False, eq=False)
class Design(_Shown):
    """Controllers designed on a model file, as ``cartctl design`` makes them.

    Attributes
    ----------
    designs : Designs
        Per motor: the runtime controller, its figures (``entry``) and its simulated step.
    model_path : Path
        The model file designed on (recorded in the controller file).
    """

    designs: Designs
    model_path: Path
    period_s: float

    @property
    def request(self) -> DesignRequest:
        return self.designs.request

    def __getitem__(self, motor: str) -> dict[str, Any]:
        """One motor's figures: gains, margins, closed-loop poles, the simulated step."""
        return self.designs.motors[_has(self.designs.motors, motor, "design")].entry

    def command(self) -> str:
        """The ``cartctl design`` command that makes this design."""
        argv = ["design", *self.request.to_argv(str(self.model_path))]
        if len(self.designs.motors) == 1:  # one motor: the command's --motor
            argv += ["--motor", *self.designs.motors]
        return "cartctl " + shlex.join(argv)

    def controller_file(self, out: str | Path | None = None) -> ControllerFile:
        """The controller file, as ``cartctl design --out OUT`` writes it (its header's command
        with ``--out OUT`` when ``out`` is given)."""
        command = self.command() + ("" if out is None else " " + shlex.join(["--out", str(out)]))
        return controller_file(self.designs, self.model_path, command=command,
                               period_s=self.period_s)  # fmt: skip

    def save(self, path: str | Path) -> Path:
        """Write the controller file; ``cartctl run --controller PATH`` runs it."""
        save_controller(self.controller_file(path), check_output_file(path, "save"))
        return Path(path)

    def _summary(self) -> _Table:
        rows = []
        for m, motor in self.designs.motors.items():
            figures = {**motor.entry, **motor.entry.get("step", {})}
            cells = (number(figures.get(k), 3) for k in _DESIGN_COLUMNS)
            rows.append((m, _gains(motor.entry), *cells))
        method = "PI" if self.request.method == "pi" else "pole placement"
        title = (f"Design: {method} on {self.model_path}, "
                 f"Ts = {number(self.period_s)} s (step {number(self.request.step_rad_s)} rad/s "
                 f"on the model)")  # fmt: skip
        first = min(self.designs.motors)
        hint = f"as `{self.command()}`; design[{first!r}] has every figure; .save(path)"
        return title, ("motor", "gains", *_DESIGN_COLUMNS.values()), rows, hint


_RUN_COLUMNS = {  # a figure of the run summary's motor: its header
    "overshoot_percent": "overshoot (%)",
    "settling_time_s": "settling (s)",
    "rise_time_s": "rise (s)",
    "steady_state_error": "steady-state error (rad/s)",
    "rms_error": "RMS error (rad/s)",
    "max_abs_voltage": "max |V| (V)",
}


@dataclass(frozen=True, repr=False, eq=False)
class SimulationResult(_Shown):
    """A simulated closed-loop run.

    Attributes
    ----------
    columns : dict of str to ndarray
        The trace's columns (``time_s``, ``voltage_a``, ``speed_a``, ``reference_a``,
        ``estimate_a``, ``true_speed_a`` …); the last row is the stop row.
    summary : dict
        The run summary of ``cartctl run --json`` (overshoot, settling, errors per motor).
    controller, plant, reference : str
        What ran, on which plant, following which reference (for titles).
    """

    columns: dict[str, NDArray[np.float64]]
    summary: dict[str, Any]
    failure: str | None = None
    controller: str = ""
    plant: str = ""
    reference: str = ""
    motors: tuple[str, ...] = field(default=MOTORS)

    def what(self, sep: str = ", ") -> str:
        """What ran, on which plant, following which reference (``sep`` after what ran)."""
        where = [f"plant {self.plant}" if self.plant else "",
                 f"reference {self.reference}" if self.reference else ""]  # fmt: skip
        return (self.controller or "a controller") + sep + ", ".join(p for p in where if p)

    def _summary(self) -> _Table:
        s = self.summary
        rows = [(m, *(number(s["motors"][m].get(k), 3) for k in _RUN_COLUMNS))
                for m in self.motors if m in s.get("motors", {})]  # fmt: skip
        failed = f"; stopped early: {self.failure}" if self.failure else ""
        title = (f"SimulationResult: {self.what()}, {s.get('ticks')} ticks "
                 f"({number(s.get('duration_s'))} s){failed}")  # fmt: skip
        on = s.get("metrics_signal", "speed").replace("_", " ")
        hint = f"metrics on the {on}; .plot(), .columns, .to_dataframe()"
        return title, ("motor", *_RUN_COLUMNS.values()), rows, hint

    def to_dataframe(self) -> Any:
        """The columns as a pandas DataFrame (``pip install "cartctl[pandas]"``)."""
        try:
            import pandas as pd
        except ImportError:
            raise InputError('to_dataframe needs pandas: pip install "cartctl[pandas]"') from None
        return pd.DataFrame(self.columns)

    def plot(self, motor: str = "both", ax: Any = None) -> Any:
        """Speed, reference and voltage over time (matplotlib); returns the figure.

        The stop row is not drawn, so the voltage does not seem to drop to 0 V at the end.

        Parameters
        ----------
        motor : {'both', 'a', 'b'}
            One column of axes per motor.
        ax : (Axes, Axes), optional
            For one motor: the speed axes and the voltage axes to draw in.
        """
        motors = self.motors if motor == "both" else (motor,)
        if any(m not in self.motors for m in motors):
            raise InputError(f"motor must be 'a', 'b' or 'both', got {motor!r}")
        if ax is None:
            import matplotlib.pyplot as plt

            fig, grid = plt.subplots(2, len(motors), sharex=True, squeeze=False,
                                     figsize=(4 + 4.5 * len(motors), 6), layout="constrained")  # fmt: skip
            pairs = [(grid[0][i], grid[1][i]) for i in range(len(motors))]
        else:
            if len(motors) != 1 or np.shape(ax) != (2,):
                raise InputError("axes: give (speed_axes, voltage_axes) for one motor")
            pairs = [tuple(ax)]
            fig = pairs[0][0].figure
        columns = self.columns
        # without the stop row (the zero-volt command a run ends with)
        drawn = {k: np.asarray(v, dtype=float)[: max(1, len(v) - 1)] for k, v in columns.items()}
        time_s = drawn["time_s"]
        for m, (top, bottom) in zip(motors, pairs, strict=True):
            top.plot(time_s, drawn[f"reference_{m}"], "k--", label="reference")
            top.plot(time_s, drawn[f"speed_{m}"], label="measured speed")
            for name, label in (("true_speed", "true speed"), ("estimate", "estimate")):
                values = columns.get(f"{name}_{m}")
                if (values is not None and np.isfinite(values).any()
                        and not np.array_equal(values, columns[f"speed_{m}"])):  # fmt: skip
                    top.plot(time_s, drawn[f"{name}_{m}"], label=label, alpha=0.8)
            top.set_title(f"motor {m}")
            top.set_ylabel("speed (rad/s)")
            bottom.step(time_s, drawn[f"voltage_{m}"], where="post", color="C3",
                        label="commanded voltage")  # fmt: skip
            bottom.set_ylabel("voltage (V)")
            bottom.set_xlabel("time (s)")
            for axes in (top, bottom):
                axes.legend(loc="lower right", fontsize="small")
                axes.grid(True, alpha=0.3)
        fig.suptitle("Closed-loop run: " + self.what(sep="\n"))
        return fig
