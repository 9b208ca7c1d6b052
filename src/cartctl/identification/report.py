"""``cartctl identify --report DIR``: the figures of :mod:`~cartctl.identification.figures` and
``summary.md`` with the residual tests, θ ± σ(θ), the fits and the order table."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cartctl.data.modelfile import ModelFile
from cartctl.data.outputs import writing
from cartctl.data.trace import Trace
from cartctl.identification import figures
from cartctl.identification.etfe import etfe, find_period
from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, MotorIdentification
from cartctl.measures.numfmt import markdown_table
from cartctl.model import ArxModel


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
    return text.replace("\n", " ")


def _table(rows: Sequence[Mapping[str, Any]]) -> str:
    columns = list(dict.fromkeys(str(name) for row in rows for name in row))
    cells = [{str(k): v for k, v in row.items()} for row in rows]
    body = [[_cell(r.get(c)) for c in columns] for r in cells]
    return markdown_table([_cell(c) for c in columns], body)


def write_summary(out_dir: Path, *, title: str, sections: Sequence[ReportSection]) -> Path:
    """Write ``out_dir/summary.md`` (the title, then each section's text, figures and table)
    and return its path."""
    out_dir = Path(out_dir)
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
    with writing(path):  # a full disk: a fault naming the file, as a figure's
        path.write_text("\n".join(lines), encoding="utf-8")
    return path


def _fit_text(value: float | None) -> str:
    return "diverges" if value is None or not math.isfinite(value) else f"{value:.2f}"


def _std(std: float, value: float) -> str:
    return "0" if abs(std) < 1e-9 * abs(value) else f"{std:.2g}"


def _row(label: str, model: ArxModel, names: list[str], std: Any, fits: Mapping[str, Any]) -> dict:
    row: dict[str, Any] = {"model": label, "nk": model.nk}
    for i, (name, value) in enumerate(zip(names, model.theta, strict=False)):
        unit = "–" if i < model.na else "rad/s/V"
        spread = "" if std is None else f" ± {_std(std[i], value)}"
        row[f"{name} ({unit})"] = f"{value:.4g}{spread}"
    sim, pred = fits["fit_simulation_percent"], fits["fit_prediction_percent"]
    row |= {"fit sim (%)": _fit_text(sim), "fit pred (%)": _fit_text(pred)}
    poles = ", ".join(f"{r.freq_hz:.2f}" for r in model.poles() if r.freq_hz is not None)
    return row | {"DC gain (rad/s/V)": f"{model.dc_gain():.4g}", "poles (Hz)": poles}


def fit_rows(
    res: MotorIdentification, compared: Mapping[str, ArxModel] | None = None
) -> list[dict[str, Any]]:
    """A table row per fitted variant (θ ± σ, fits, DC gain, pole frequencies), then per
    compared model (θ, its fits on the same data)."""
    rows = []
    names: list[str] = []
    for label, fit in res.variants().items():
        names = fit.theta_names()
        rows.append(_row(label, fit.model, names, fit.theta_std, fit.to_dict()))
    compared = compared or {}
    for label, f in res.diagnostics.compared_fits(compared).items():
        model = compared[label]
        general = [f"a{i + 1}" for i in range(model.na)] + [f"b{j}" for j in range(model.nb)]
        own = names if model.theta.size == len(names) else general
        rows.append(_row(label, model, own, None, f))
    return rows


def _motor_section(
    res: MotorIdentification, trace: Trace, out_dir: Path, compare: Mapping[str, ModelFile]
) -> ReportSection:
    m, diag, on = res.motor, res.diagnostics, res.diagnostics.fit_on
    y, u = trace.speed(m), trace.voltage(m)
    variants = res.variants()
    files = {f"{Path(p).stem} ({p})": mf.motors[m] for p, mf in compare.items() if m in mf.motors}
    compared = {label: fit.model for label, fit in variants.items()} | files
    chosen = next(label for label, fit in variants.items() if fit is res.chosen)
    period = find_period(u)
    response = etfe(y, u, trace.period_s, period_ticks=period)
    simulated = {label: model.simulate(u) for label, model in compared.items()}
    png = {k: out_dir / f"{k}_{m}.png" for k in ("etfe", "pzmap", "simulation", "residuals")}
    images = [
        figures.plot_etfe(
            response,
            {chosen: compared[chosen]} | compared,
            png["etfe"],
            title=f"Motor {m}: empirical transfer function and models",
            band=diag.band,
        ),
        figures.plot_pzmap(compared, png["pzmap"], title=f"Motor {m}: pole-zero map"),
        figures.plot_step_validation(
            trace.time_s,
            u,
            y,
            simulated,
            png["simulation"],
            title=f"Motor {m}: measured and simulated speed ({trace.source})",
        ),
        figures.plot_residuals(
            diag.residuals,
            png["residuals"],
            title=f"Motor {m}: residual tests ({chosen}, {on} data)",
        ),
    ]
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
    if n := res.cycles_averaged:
        paragraphs.append(f"{n} whole excitation cycles were averaged before the ARX fit.")
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
    first = traces[0]
    io_png = figures.plot_io(
        first, list(result.motors), out / "io.png", title=f"Experiment: {first.source}"
    )
    what = f"{request.method.upper()} (na = {request.na}, nb = {request.nb})"
    what += f", prefilter {request.prefilter.describe()}" if request.prefilter else ", no prefilter"
    sections: list[ReportSection | None] = [
        ReportSection(
            heading="Experiment",
            text=f"Data: {', '.join(str(t.source) for t in traces)}. Method: {what}. "
            f"Ts = {result.period_s * 1e3:g} ms.",
            images=[io_png.relative_to(out)],
        )
    ]
    for motor, res in result.motors.items():
        trace = next(t for t in traces if (t.voltage(motor) != 0.0).any())
        sections += [_motor_section(res, trace, out, compare or {}), _orders_section(res)]
    kept = [s for s in sections if s is not None]
    return write_summary(out, title="Motor identification", sections=kept)
