"""``cartctl identify --report DIR``: the figures (input and output, measured against simulated
speed; the analysis figures are in :mod:`~cartctl.identification.figures`) and ``summary.md``
with the residual tests, θ ± σ(θ), the fits and the order table."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cartctl.data.modelfile import ModelFile
from cartctl.data.trace import Trace
from cartctl.errors import InputError
from cartctl.identification.etfe import etfe, find_period
from cartctl.identification.figures import (
    color,
    figure,
    plot_etfe,
    plot_pzmap,
    plot_residuals,
    save,
)
from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, MotorIdentification
from cartctl.measures.metrics import fit_percent
from cartctl.measures.numfmt import markdown_table
from cartctl.model import ArxModel


def plot_io(
    trace: Trace,
    motors: Sequence[str],
    path: Path,
    *,
    title: str,
    zoom_s: tuple[float, float] | None = None,
) -> Path:
    """Input and output of an experiment per motor (report, figures 3 and 11); returns ``path``.
    Per motor voltage (V) above speed (rad/s), and the speed again over ``zoom_s`` (s)."""
    if not motors:
        raise InputError("plot_io needs at least one motor, e.g. ('a', 'b')")
    if zoom_s is not None and not zoom_s[0] < zoom_s[1]:
        raise InputError(f"zoom window must be (start_s, end_s) with start < end, got {zoom_s}")
    t = trace.time_s
    rows = 3 if zoom_s is not None else 2
    with figure(max(9.0, 5.5 * len(motors) + 0.5), 2.4 * rows + 0.8) as fig:
        grid = fig.add_gridspec(rows, len(motors), height_ratios=[1.0, 1.4, 1.4][:rows])
        first = None
        for j, motor in enumerate(motors):
            voltage, speed = trace.voltage(motor), trace.speed(motor)
            ax_v = fig.add_subplot(grid[0, j], sharex=first)
            first = first or ax_v
            ax_w = fig.add_subplot(grid[1, j], sharex=first)
            ax_v.plot(t, voltage, drawstyle="steps-post", color="tab:blue")
            ax_v.set_title(f"Motor {motor.upper()}")
            ax_v.set_ylabel("voltage (V)")
            ax_w.plot(t, speed, color="tab:red", linewidth=1.0)
            ax_w.set_ylabel("speed (rad/s)")
            ax_v.tick_params(labelbottom=False)
            if zoom_s is None:
                ax_w.set_xlabel("time (s)")
                continue
            ax_w.axvspan(*zoom_s, color="0.85", zorder=0)
            ax_z = fig.add_subplot(grid[2, j])
            inside = (t >= zoom_s[0]) & (t <= zoom_s[1])
            ax_z.plot(t[inside], speed[inside], color="tab:red", linewidth=1.2)
            ax_z.set_xlim(*zoom_s)
            ax_z.set_ylabel("speed (rad/s)")
            ax_z.set_xlabel("time (s)")
            ax_z.set_title(f"zoom {zoom_s[0]:g}–{zoom_s[1]:g} s", fontsize=10)
        if len(t) and first is not None:
            first.set_xlim(t[0], t[-1])
        fig.suptitle(title)
        return save(fig, path)


def plot_step_validation(
    time_s: ArrayLike,
    voltage: ArrayLike,
    measured: ArrayLike,
    simulated: Mapping[str, ArrayLike],
    path: Path,
    *,
    title: str,
) -> Path:
    """Measured against simulated speed (rad/s, label → array, the legend with each fit in %)
    above |error|, under the voltage (V) (report, figures 6, 7); returns ``path``."""
    t = np.asarray(time_s, dtype=float)
    series = {"voltage": np.asarray(voltage, dtype=float), "measured": np.asarray(measured, float)}
    series |= {f"simulated[{k!r}]": np.asarray(v, dtype=float) for k, v in simulated.items()}
    for name, values in series.items():
        if values.ndim != 1 or values.shape != t.shape or t.ndim != 1:
            raise InputError(
                f"{name} must be 1-D with one value per time step ({t.shape}), got {values.shape}"
            )
    y = series["measured"]
    with figure(10.0, 7.5) as fig:
        ax_u, ax_y, ax_e = fig.subplots(3, 1, sharex=True, height_ratios=[1.0, 2.6, 1.6])
        ax_u.plot(t, series["voltage"], drawstyle="steps-post", color="tab:blue")
        ax_u.set_ylabel("voltage (V)")
        ax_y.plot(t, y, color="black", linewidth=2.0, label="measured")
        for i, (label, given) in enumerate(simulated.items()):
            sim = np.asarray(given, dtype=float)
            fit = fit_percent(y, sim)
            ax_y.plot(t, sim, color=color(i), label=f"{label} (fit {fit:.1f} %)")
            ax_e.plot(t, np.abs(y - sim), color=color(i))
        ax_y.set_ylabel("speed (rad/s)")
        ax_e.set_ylabel("|error| (rad/s)")
        ax_e.set_xlabel("time (s)")
        if t.size:
            ax_e.set_xlim(t[0], t[-1])
        fig.legend(*ax_y.get_legend_handles_labels(), loc="outside lower center", ncols=3)
        fig.suptitle(title)
        return save(fig, path)


@dataclass(frozen=True)
class ReportSection:
    """One ``## heading`` of ``summary.md``: markdown text, figures (relative to the summary's
    folder; absolute paths are made relative) and an optional table (rows of column → value,
    columns in order of first appearance, floats to 4 significant digits)."""

    heading: str
    text: str = ""
    images: Sequence[str | Path] = ()
    table: Sequence[Mapping[str, Any]] | None = None


def _cell(value: Any) -> str:
    if value is None:
        return ""
    text = f"{float(value):.4g}" if isinstance(value, float | np.floating) else str(value)
    return text.replace("|", "\\|").replace("\n", " ")


def _table(rows: Sequence[Mapping[str, Any]]) -> str:
    columns: list[str] = []
    for row in rows:
        columns += [str(name) for name in row if str(name) not in columns]
    cells = [{str(k): v for k, v in row.items()} for row in rows]
    return markdown_table([_cell(c) for c in columns],
                          [[_cell(r.get(c)) for c in columns] for r in cells])  # fmt: skip


def write_summary(out_dir: Path, *, title: str, sections: Sequence[ReportSection]) -> Path:
    """Write ``out_dir/summary.md`` (the title, then each section's text, figures and table)
    and return its path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = [f"# {title}", ""]
    for section in sections:
        lines += [f"## {section.heading}", ""]
        if section.text.strip():
            lines += [section.text.strip(), ""]
        for image in section.images:
            image = Path(image)
            rel = Path(os.path.relpath(image, out_dir)) if image.is_absolute() else image
            lines += [f"![{rel.stem}]({rel.as_posix()})", ""]
        if section.table:
            lines += [_table(section.table), ""]
    path = out_dir / "summary.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def _fit_text(value: float | None) -> str:
    return "diverges" if value is None or not math.isfinite(value) else f"{value:.2f}"


def _std(std: float, value: float) -> str:
    return "0" if abs(std) < 1e-9 * abs(value) else f"{std:.2g}"


def _row(label: str, model: ArxModel, names: list[str], std: Any, sim: Any, pred: Any) -> dict:
    row: dict[str, Any] = {"model": label, "nk": model.nk}
    na = model.na
    for i, (name, value) in enumerate(zip(names, model.theta, strict=False)):
        unit = "–" if i < na else "rad/s/V"
        row[f"{name} ({unit})"] = f"{value:.4g}" + (
            "" if std is None else f" ± {_std(std[i], value)}"
        )
    row["fit sim (%)"] = _fit_text(sim)
    row["fit pred (%)"] = _fit_text(pred)
    row["DC gain (rad/s/V)"] = f"{model.dc_gain():.4g}"
    row["poles (Hz)"] = ", ".join(
        f"{r.freq_hz:.2f}" for r in model.poles() if r.freq_hz is not None
    )
    return row


def fit_rows(
    res: MotorIdentification, compared: Mapping[str, ArxModel] | None = None
) -> list[dict[str, Any]]:
    """A table row per fitted variant (θ ± σ, fits, DC gain, pole frequencies), then per
    compared model (θ, its fits on the same data)."""
    rows = []
    names: list[str] = []
    for label, fit in res.variants().items():
        names = fit.theta_names()
        rows.append(_row(label, fit.model, names, fit.theta_std, fit.fit_simulation_percent,
                         fit.fit_prediction_percent))  # fmt: skip
    if compared:
        fits = res.diagnostics.compared_fits(compared)
        for label, model in compared.items():
            f = fits[label]
            own = (
                names
                if model.theta.size == len(names)
                else [f"a{i + 1}" for i in range(model.na)] + [f"b{j}" for j in range(model.nb)]
            )
            rows.append(_row(label, model, own, None, f["fit_simulation_percent"],
                             f["fit_prediction_percent"]))  # fmt: skip
    return rows


def _motor_section(
    res: MotorIdentification, trace: Trace, out_dir: Path, compare: Mapping[str, ModelFile]
) -> ReportSection:
    m = res.motor
    y, u, ts = trace.speed(m), trace.voltage(m), trace.period_s
    models: dict[str, ArxModel] = {label: fit.model for label, fit in res.variants().items()}
    files = {f"{Path(path).stem} ({path})": mf.motors[m] for path, mf in compare.items()
             if m in mf.motors}  # fmt: skip
    compared = models | files
    chosen = next(label for label, fit in res.variants().items() if fit is res.chosen)
    ordered = {chosen: models[chosen]} | compared
    diag = res.diagnostics
    images = []
    period = find_period(u)
    response = etfe(y, u, ts, period_ticks=period)
    images.append(plot_etfe(response, ordered, out_dir / f"etfe_{m}.png",
                            title=f"Motor {m}: empirical transfer function and models",
                            band=diag.band))  # fmt: skip
    images.append(
        plot_pzmap(compared, out_dir / f"pzmap_{m}.png", title=f"Motor {m}: pole-zero map")
    )
    simulated = {label: model.simulate(u) for label, model in compared.items()}
    images.append(
        plot_step_validation(trace.time_s, u, y, simulated, out_dir / f"simulation_{m}.png",
                             title=f"Motor {m}: measured and simulated speed ({trace.source})")
    )  # fmt: skip
    on = diag.fit_on
    etfe_kind = (
        f"whole periods of {period} ticks, averaged over {response.n_segments}"
        if period
        else "the whole record (input not periodic)"
    )
    paragraphs = [
        "Fits: *sim* is the model simulated from the input alone on the raw data; *pred* is the "
        "one-step-ahead prediction on the fitted data. ± is one standard deviation."
        if on == "estimation"
        else "Fits on the validation data: *sim* simulated from its input alone, *pred* "
        "predicted one step ahead. ± is one standard deviation.",
        f"Empirical transfer function: {etfe_kind}.",
    ]
    if (d := res.delay) is not None:
        evidence = ", ".join(
            f"nk = {nk}: {rms:.4g} rad/s"
            for nk, rms in zip(d.candidates, d.residual_rms, strict=True)
        )
        alone = "" if d.nk_alone is None else f"; on its own: nk = {d.nk_alone}"
        paragraphs.append(
            f"Delay estimated as nk = {d.nk}, one for all motors identified, from their joint "
            f"evidence (this motor's equation-error RMS per candidate: {evidence}{alone})."
        )
    if res.cycles_averaged:
        paragraphs.append(
            f"{res.cycles_averaged} whole excitation cycles were averaged before the ARX fit."
        )
    images.append(plot_residuals(diag.residuals, out_dir / f"residuals_{m}.png",
                                 title=f"Motor {m}: residual tests ({chosen}, {on} data)"))  # fmt: skip
    paragraphs.append(
        f"Residual tests of the {chosen} model on the {on} data: {diag.residuals.summary()}."
    )
    if diag.band is not None:
        paragraphs.append(f"Bode bands of the {chosen} model: {diag.band.to_dict()['method']}.")
    return ReportSection(
        heading=f"Motor {m}",
        text="\n\n".join(paragraphs),
        images=[p.relative_to(out_dir) for p in images],
        table=fit_rows(res, files),
    )


def _orders_section(res: MotorIdentification) -> ReportSection | None:
    table = res.diagnostics.orders
    if table is None:
        return None
    heads = ["na", "nb", "nk", "params", "loss V ((rad/s)²)", "AIC (–)", "FPE ((rad/s)²)"]
    heads += [f"sim fit, {table.fit_on} (%)", "best"]
    rows = []
    for r in table.rows:
        cells = [r.na, r.nb, r.nk, r.params, *table.cells(r), ", ".join(table.marks(r))]
        rows.append(dict(zip(heads, cells, strict=True)))
    return ReportSection(
        heading=f"Motor {res.motor}: orders and delay",
        text=f"ARX fits on N = {table.n_equations} common equations. V is the mean squared "
        "equation error, AIC = N ln V + 2d, FPE = V (1 + d/N) / (1 − d/N) with d = na + nb; the "
        f"fit is the simulation's NRMSE on the {table.fit_on} data.",
        table=rows,
    )


def write_identify_report(
    out_dir: str | Path,
    result: IdentifyResult,
    traces: Sequence[Trace],
    request: IdentifyRequest,
    compare: Mapping[str, ModelFile] | None = None,
) -> Path:
    """Write the PNG figures (from the first trace that drives each motor) and ``summary.md``
    into ``out_dir``; returns the summary's path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    first = traces[0]
    io_png = plot_io(
        first, list(result.motors), out / "io.png", title=f"Experiment: {first.source}"
    )
    what = f"{request.method.upper()} (na = {request.na}, nb = {request.nb})"
    what += f", prefilter {request.prefilter.describe()}" if request.prefilter else ", no prefilter"
    sections = [
        ReportSection(
            heading="Experiment",
            text=f"Data: {', '.join(str(t.source) for t in traces)}. Method: {what}. "
            f"Ts = {result.period_s * 1e3:g} ms.",
            images=[io_png.relative_to(out)],
        )
    ]
    for motor, res in result.motors.items():
        trace = next(t for t in traces if (t.voltage(motor) != 0.0).any())
        sections.append(_motor_section(res, trace, out, compare or {}))
        orders = _orders_section(res)
        if orders is not None:
            sections.append(orders)
    return write_summary(out, title="Motor identification", sections=sections)
