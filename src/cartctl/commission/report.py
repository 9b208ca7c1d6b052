"""What commissioning writes: ``summary.md`` (rewritten after each stage, so a run stopped anywhere
leaves a readable summary), PNG figures, and one Rerun recording per stage: its series on the
``time`` timeline, its section as a Markdown note at ``commission/<stage>``, a trace under the
run's entity paths and layout (so ``cartctl review`` shows it as a run). Recording problems never
stop commissioning: they come back as text for the summary."""

from __future__ import annotations

import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from cartctl.commission import checks, tuning
from cartctl.data.outputs import writing
from cartctl.data.trace import Trace
from cartctl.measures.numfmt import format_fixed, markdown_table
from cartctl.sinks.rerun_layout import ENTITY_PATHS, blueprint
from cartctl.sinks.rerun_problems import cut_to_whole_messages, file_failure
from cartctl.sinks.rerun_sink import APPLICATION_ID
from cartctl.tune.batch import later_command

Line = tuple[NDArray[np.float64], NDArray[np.float64]]  # (time s, values)
Series = dict[str, Line]  # by entity path


def fmt(value: float | None, digits: int = 2, scale: float = 1.0) -> str:
    """A figure for a table, ``scale`` × ``value`` to ``digits`` decimals ('—' for None)."""
    return format_fixed(None if value is None else value * scale, digits)


@dataclass
class Report:
    """The sections (heading: Markdown body) of ``summary.md``, rewritten on each :meth:`add`."""

    path: Path
    title: str
    sections: dict[str, str] = field(default_factory=dict)

    def add(self, heading: str, body: str) -> None:
        """Add a section (or replace it, moving it last) and rewrite the file, via a temporary one
        so that the old one stays whole until then."""
        self.sections.pop(heading, None)
        self.sections[heading] = body
        parts = [f"# {self.title}", *(f"## {h}\n\n{b.strip()}" for h, b in self.sections.items())]
        tmp = self.path.with_suffix(".md.tmp")
        try:
            tmp.write_text("\n\n".join(parts) + "\n", encoding="utf-8")
            tmp.replace(self.path)
        except OSError:  # a full disk: no half-written temporary left behind
            tmp.unlink(missing_ok=True)
            raise


def plot_lines(path: Path, title: str, panels: Sequence[tuple[str, Mapping[str, Line]]]) -> None:
    """Stacked panels of labelled lines: ``panels`` = [(y label, {legend: (x, y)}), ...]."""
    from matplotlib.figure import Figure  # no pyplot: no global state, the Agg canvas on saving

    fig = Figure(figsize=(8, 2.6 * len(panels)))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)
    for ax, (ylabel, lines) in zip(axes[:, 0], panels, strict=True):
        for label, (x, y) in lines.items():
            ax.plot(x, y, label=label, lw=1.2)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    with writing(path):  # a full disk: a fault naming the figure
        fig.savefig(path, dpi=100)


def _table(rows: Sequence[Sequence[tuple[str, str]]]) -> str:
    """A Markdown table of rows of (header, cell); the headers are the first row's."""
    return markdown_table([h for h, _ in rows[0]], [[cell for _, cell in row] for row in rows])


def checks_body(loop_delay_ticks: int | None, checks: Mapping[str, Any], plant: str,
                amplitude: Any | None) -> str:  # fmt: skip
    """The checks section: the plant, the loop delay, each motor's figures, the amplitude rule."""
    rows = [
        [
            ("motor", c.motor),
            ("direction", c.direction),
            ("pulse turn (rad)", fmt(c.pulse_turn_rad, 3)),
            ("other wheel (rad)", fmt(c.other_turn_rad, 3)),
            ("breakaway (V)", fmt(c.breakaway_v, 2)),
            ("gain (rad/s/V)", fmt(c.gain_rad_s_v, 2)),
        ]
        for c in checks.values()
    ]
    body = (
        f"Plant: {plant}. Loop delay: {loop_delay_ticks} tick(s) (measurement to applied "
        "voltage).\n\n" + _table(rows)
    )
    if amplitude is not None:
        body += f"\n\nExcitation amplitude: **{amplitude.voltage_v:g} V**. Rule: {amplitude.rule}."
    return body + "\n\nFiles: checks.csv, checks.rrd, checks.png."


def model_body(result: Any, verdicts: Mapping[str, Any], model_name: str) -> str:
    """The identification section: θ, nk, DC gain, validation figures, verdicts."""
    rows = []
    for m, r in result.motors.items():
        v, model = verdicts[m], r.chosen.model
        cross = f"{v.cross_outside}/{v.cross_lags} ({v.cross_ratio:.1f}×)"
        verdict = "pass" if not v.problems else "FAIL: " + "; ".join(v.problems)
        rows.append(
            [
                ("motor", m),
                ("θ = [a1, a2, b0 …]", ", ".join(f"{x:.4g}" for x in model.theta)),
                ("nk", str(model.nk)),
                ("DC gain (rad/s/V)", fmt(model.dc_gain(), 3)),
                ("validation fit (%)", fmt(v.validation_fit_percent, 1)),
                ("max |pole|", fmt(v.pole_radius, 3)),
                ("cross-corr. lags outside (max/bound)", cross),
                ("white", "yes" if v.white else "no"),
                ("verdict", verdict),
            ]
        )
    return (
        _table(rows)
        + "".join(f"\n\n{note}." for note in result.notes)
        + f"\n\nFiles: {model_name}, identification.rrd, identification.png."
    )


def _cell(r: dict[str, Any], part: str, key: str, digits: int, scale: float = 1.0) -> str:
    """A figure of a tuning row's ``part`` ('nominal', 'worst'); blank for an unscored row."""
    return fmt(r[part][key], digits, scale) if part in r else ""


def tuning_body(result: tuning.TuningResult, command: str) -> str:
    """The tuning section: the rule, the grid's table (worse of motors a and b), the choice."""
    later = " and ".join(f"{f * 10:g} ms" for f in tuning.LATER_FRACTIONS)
    rows = []
    for row in result.rows:
        r = tuning.row_summary(row)
        s = r["settings"]
        mark = "**→**" if row.index == result.chosen.index else ("*" if r.get("pareto") else "")
        timing = " / ".join(fmt(e["overshoot_percent"], 1) for e in r.get("timing", ()))
        rows.append(
            [
                ("", mark),
                ("#", str(r["index"])),
                ("settling target (ms)", f"{s['settling-time'] * 1e3:g}"),
                ("overshoot target (%)", f"{s['overshoot']:g}"),
                (
                    "nominal overshoot (%)",
                    _cell(r, "nominal", "overshoot_percent", 1) or r["status"],
                ),
                ("nominal settling (ms)", _cell(r, "nominal", "settling_time_s", 0, 1e3)),
                ("worst overshoot (%)", _cell(r, "worst", "overshoot_percent", 1)),
                ("worst settling (ms)", _cell(r, "worst", "settling_time_s", 0, 1e3)),
                (f"timing plants overshoot (%) ({later})", timing),
                ("peak voltage (V)", _cell(r, "nominal", "peak_voltage_v", 1)),
            ]
        )
    return (
        f"Pole placement with a Kalman estimator, designed for a loop delay of "
        f"{result.design_fixed['loop_delay_ticks']} tick(s); each setting run in the simulated "
        f"loop ({tuning.REFERENCE}, {tuning.DURATION_S:g} s) on the model (nominal), on "
        f"{tuning.PLANTS} plants drawn from its uncertainty (θ ± its standard deviation, DC gain "
        f"±10 %, loop delay −1/0/+1 tick; worst = over them, the model and the timing plants) "
        f"and on the model with each command landing {later} later (timing plants).\n\n"
        f"Choice: among the settings that settle on every plant, with overshoot ≤ "
        f"{tuning.MAX_OVERSHOOT_PERCENT:g} % on the model and on the timing plants and nominal "
        f"settling ≤ {tuning.MAX_SETTLING_S * 1e3:g} ms, the lowest worst-case overshoot, then "
        f"the fastest nominal settling (`tune --robust --choose best`'s rule).\n\n"
        + _table(rows)
        + f"\n\n→ chosen; *: on the robust Pareto front. Controller: `{command}`.\n\n"
        + "".join(f"Setting #{i} passed over: {why}.\n\n" for i, why in result.refused)
        + "Files: controller.toml, tuning.rrd, tuning.png."
    )


def tuning_steps(controller_path: Path, model_path: Path, png: Path) -> Series:
    """The chosen controller's simulated step on the model and the timing plants (series, PNG)."""
    from cartctl.data.modelfile import load_models
    from cartctl.design.controllerfile import build_controllers, load_controller
    from cartctl.plants.sim import ArxPlant
    from cartctl.reference import reference_signal
    from cartctl.runtime.loop import run_in_memory

    file = load_controller(controller_path)
    models = load_models(model_path)
    n = round(tuning.DURATION_S / models.period_s)
    plants = {"model": [models.motor(m) for m in "ab"]}
    for f in tuning.LATER_FRACTIONS:
        plants[f"{f * 10:g} ms later"] = [later_command(models.motor(m), f) for m in "ab"]
    refs = {m: reference_signal(tuning.REFERENCE, n, models.period_s, m) for m in "ab"}
    series: Series = {}
    speed, volts = {}, {}
    for name, (a, b) in plants.items():
        columns, _ = run_in_memory(ArxPlant(a, b), build_controllers(file), refs,
                                   period_s=models.period_s,
                                   voltage_limit_v=file.voltage_limit_v)  # fmt: skip
        t, key = columns["time_s"], name.replace(" ", "_")
        series |= {f"tuning/{key}/{q}_{m}": (t, columns[f"{q}_{m}"])
                   for m in "ab" for q in ("speed", "voltage")}  # fmt: skip
        speed[f"motor a, {name}"] = (t, columns["speed_a"])
        volts[f"motor a, {name}"] = (t, columns["voltage_a"])
        series["tuning/reference"] = (t, columns["reference_a"])
    plot_lines(png, "The chosen controller's simulated step", [
        ("speed (rad/s)", speed), ("voltage (V)", volts)])  # fmt: skip
    return series


_VERIFIED = (
    ("overshoot", "overshoot_percent", "%", 2, 1.0),
    ("settling", "settling_time_s", "ms", 0, 1e3),
)


def _measured(checked: checks.Verification, key: str, digits: int, scale: float) -> str:
    """A measured figure; a settling time of None (JSON null, as in run's) is 'not settled'."""
    value = checked.measured[key]
    return (
        "not settled" if value is None and key == "settling_time_s" else fmt(value, digits, scale)
    )


def missed_bounds(checked: checks.Verification) -> str:
    """The figures beyond their pass bound, e.g. 'settling: not settled (bound ≤ 150 ms)'."""
    missed = []
    for label, key, unit, digits, scale in _VERIFIED:
        value, bound = checked.measured[key], checked.limits[key]
        if value is None or value > bound:
            shown = _measured(checked, key, digits, scale)
            shown = f": {shown}" if value is None else f" {shown} {unit}"
            missed.append(f"{label}{shown} (bound ≤ {bound * scale:.{digits}f} {unit})")
    return ", ".join(missed)


def verification_body(checked: checks.Verification, summary: dict[str, Any],
                      argv: list[str]) -> str:  # fmt: skip
    """The verification section: measured against predicted, the bounds, pass or fail."""
    p, lim = checked.predicted, checked.limits
    heads = ["", "measured", "predicted nominal", "predicted worst", "pass bound"]
    rows = [
        [
            f"{label} ({unit})",
            _measured(checked, k, digits, scale),
            fmt(p.get(f"nominal_{k}"), digits, scale),
            fmt(p.get(f"worst_{k}"), digits, scale),
            f"≤ {lim[k] * scale:.{digits}f}",
        ]
        for label, k, unit, digits, scale in _VERIFIED
    ]
    return (
        f"`cartctl {' '.join(argv)}` (worse of motors a and b, on the {lim['speed']} speed).\n\n"
        + markdown_table(heads, rows)
        + f"\n\n**{'PASS' if checked.passed else 'FAIL'}**. Bounds: overshoot ≤ max("
        f"{checks.TARGET_OVERSHOOT_PERCENT:g} %, predicted nominal) + a tolerance "
        f"({checks.TRUE_SPEED_TOLERANCE_PP:g} point on a true speed, half an encoder count per "
        "tick over the step more on the smoothed speed, a whole count on the bare encoder "
        f"speed); settling ≤ max({checks.TARGET_SETTLING_S * 1e3:g} ms, "
        "predicted nominal + 20 ms). The prediction is the linear model's: a cart's friction "
        "and encoder, which the model leaves out, usually add a point or two of overshoot; the "
        "bounds are the targets, the prediction is shown beside them.\n\n"
        f"Files: {Path(str(summary.get('trace'))).name}, "
        f"{Path(str(summary.get('recording'))).name}."
    )


def trace_series(trace: Trace) -> Series:
    """A trace's columns under the run's Rerun entity paths."""
    t = np.asarray(trace.time_s, dtype=float)
    return {ENTITY_PATHS[c]: (t, np.asarray(v, dtype=float))
            for c, v in trace.columns().items() if c in ENTITY_PATHS}  # fmt: skip


def record_stage(path: Path, series: Series, note: str, stage: str, *,
                 layout: bool = False) -> str | None:  # fmt: skip
    """Write ``series`` and ``note`` (Markdown) to ``path``, with the run's layout if ``layout``;
    returns a problem's description, or None."""
    try:
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
        rec.set_sinks(rr.FileSink(path))
        rec.send_recording_name(path.stem)
        if layout:
            rec.send_blueprint(blueprint())
        markdown = rr.TextDocument(note, media_type=rr.MediaType.MARKDOWN)
        rec.log(f"commission/{stage}", markdown, static=True)
        for entity, (time_s, values) in series.items():
            rec.send_columns(entity, indexes=[rr.TimeColumn("time", duration=np.asarray(time_s))],
                             columns=rr.Scalars.columns(scalars=np.asarray(values, float)))  # fmt: skip
        rec.flush(timeout_sec=5.0)
        rec.disconnect()
    except Exception as exc:  # the SDK's failures: commissioning goes on, the summary says so
        if (why := file_failure(exc, path)) is not None:  # the recording so far must read
            cut_to_whole_messages(path)
        return f"{path}: {why or exc}"  # the SDK's own log lines are off
    return None
