"""``cartctl identify --report DIR``: the figures and markdown summary of one identification.

Draws, from the same results that ``--json`` prints: the experiment's input and output, per motor
the empirical transfer function against every fitted model's Bode plot, a pole-zero map of the
fitted models (and of any ``--compare`` model files), and the measured speed against each model's
simulation. ``summary.md`` embeds them with a table of θ, σ(θ) and the fits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cartctl.data.modelfile import ModelFile
from cartctl.data.trace import Trace
from cartctl.identification.cycles import find_period
from cartctl.identification.etfe import etfe
from cartctl.identification.pipeline import IdentifyRequest, IdentifyResult, MotorIdentification
from cartctl.identification.report import (
    ReportSection,
    plot_etfe,
    plot_io,
    plot_pzmap,
    plot_step_validation,
    write_summary,
)
from cartctl.identification.residuals import plot_residuals
from cartctl.model import ArxModel


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
    """One table row per fitted variant (θ ± σ, fits, DC gain, pole frequencies), then one per
    compared model (θ, its fits on the same data)."""
    rows = []
    names: list[str] = []
    for label, fit in res.variants().items():
        names = fit.theta_names()
        rows.append(_row(label, fit.model, names, fit.theta_std, fit.fit_simulation_percent,
                         fit.fit_prediction_percent))  # fmt: skip
    if compared and res.diagnostics is not None:
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
    res: MotorIdentification,
    trace: Trace,
    out_dir: Path,
    compare: Mapping[str, ModelFile],
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
                            band=None if diag is None else diag.band))  # fmt: skip
    images.append(
        plot_pzmap(compared, out_dir / f"pzmap_{m}.png", title=f"Motor {m}: pole-zero map")
    )
    simulated = {label: model.simulate(u) for label, model in compared.items()}
    images.append(
        plot_step_validation(trace.time_s, u, y, simulated, out_dir / f"simulation_{m}.png",
                             title=f"Motor {m}: measured and simulated speed ({trace.source})")
    )  # fmt: skip
    on = "estimation" if diag is None else diag.fit_on
    text = [
        "Fits: *sim* is the model simulated from the input alone on the raw data; *pred* is the "
        "one-step-ahead prediction on the fitted data. ± is one standard deviation."
        if on == "estimation"
        else "Fits on the validation data: *sim* simulated from its input alone, *pred* "
        "predicted one step ahead. ± is one standard deviation.",
        "",
        f"Empirical transfer function: {'whole periods of ' + str(period) + ' ticks, averaged over ' + str(response.n_segments) if period else 'the whole record (input not periodic)'}.",
    ]
    if res.delay is not None:
        evidence = ", ".join(
            f"nk = {nk}: {rms:.4g} rad/s"
            for nk, rms in zip(res.delay.candidates, res.delay.residual_rms, strict=True)
        )
        text += [
            "",
            f"Delay estimated as nk = {res.delay.nk}, one for all motors identified, from their joint "
            f"evidence (this motor's equation-error RMS per candidate: {evidence}"
            + ("" if res.delay.nk_alone is None else f"; on its own: nk = {res.delay.nk_alone}")
            + ").",
        ]
    if res.cycles_averaged:
        text += [
            "",
            f"{res.cycles_averaged} whole excitation cycles were averaged before the ARX fit.",
        ]
    if diag is not None:
        images.append(plot_residuals(diag.residuals, out_dir / f"residuals_{m}.png",
                                     title=f"Motor {m}: residual tests ({chosen}, {on} data)"))  # fmt: skip
        text += [
            "",
            f"Residual tests of the {chosen} model on the {on} data: {diag.residuals.summary()}.",
        ]
        if diag.band is not None:
            text += ["", f"Bode bands of the {chosen} model: {diag.band.to_dict()['method']}."]
    return ReportSection(
        heading=f"Motor {m}",
        text="\n".join(text),
        images=[p.relative_to(out_dir) for p in images],
        table=fit_rows(res, files),
    )


def _orders_section(res: MotorIdentification) -> ReportSection | None:
    diag = res.diagnostics
    if diag is None or diag.orders is None:
        return None
    table = diag.orders
    rows = []
    for r in table.rows:
        rows.append({
            "na": r.na, "nb": r.nb, "nk": r.nk, "params": r.params,
            "loss V ((rad/s)²)": "" if r.error else f"{r.loss:.4f}",
            "AIC (–)": "" if r.error else f"{r.aic:.1f}",
            "FPE ((rad/s)²)": "" if r.error else f"{r.fpe:.4f}",
            f"sim fit, {table.fit_on} (%)": r.error or r.fit_text(),
            "best": ", ".join(table.marks(r)),
        })  # fmt: skip
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
    """Write the PNG figures and ``summary.md`` into ``out_dir``; returns the summary's path.

    The figures use the first trace that drives each motor.
    """
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
