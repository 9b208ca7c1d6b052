"""``cartctl identify --report DIR``: the figures and markdown summary of one identification.

Draws, from the same results that ``--json`` prints: the experiment's input and output, per motor
the empirical transfer function against every fitted model's Bode plot, a pole-zero map of the
fitted models (and of any ``--compare`` model files), and the measured speed against each model's
simulation. ``summary.md`` embeds them with a table of θ, σ(θ) and the fits.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cartctl.data import Trace
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
from cartctl.model import ArxModel
from cartctl.modelfile import ModelFile


def fit_rows(res: MotorIdentification) -> list[dict[str, Any]]:
    """One table row per fitted variant: θ ± σ, fits, DC gain, pole frequencies."""
    rows = []
    for label, fit in res.variants().items():
        row: dict[str, Any] = {"model": label, "nk": fit.model.nk}
        for name, value, std in zip(fit.theta_names(), fit.model.theta, fit.theta_std, strict=True):
            row[name] = f"{value:.5g} ± {std:.2g}"
        row["fit sim %"] = f"{fit.fit_simulation_percent:.2f}"
        row["fit pred %"] = f"{fit.fit_prediction_percent:.2f}"
        row["DC gain (rad/s/V)"] = f"{fit.model.dc_gain():.4g}"
        row["poles (Hz)"] = ", ".join(
            f"{r.freq_hz:.2f}" for r in fit.model.poles() if r.freq_hz is not None
        )
        rows.append(row)
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
    compared = dict(models)
    for path, mf in compare.items():
        if m in mf.motors:
            compared[f"{Path(path).stem} ({path})"] = mf.motors[m]
    images = []
    period = find_period(u)
    response = etfe(y, u, ts, period_ticks=period)
    images.append(plot_etfe(response, models, out_dir / f"etfe_{m}.png",
                            title=f"Motor {m}: empirical transfer function and models"))  # fmt: skip
    images.append(
        plot_pzmap(compared, out_dir / f"pzmap_{m}.png", title=f"Motor {m}: pole-zero map")
    )
    simulated = {label: model.simulate(u) for label, model in models.items()}
    images.append(
        plot_step_validation(trace.time_s, u, y, simulated, out_dir / f"simulation_{m}.png",
                             title=f"Motor {m}: measured and simulated speed ({trace.source})")
    )  # fmt: skip
    text = [
        "Fits: *sim* is the model simulated from the input alone on the raw data; *pred* is the "
        "one-step-ahead prediction on the fitted data. ± is one standard deviation.",
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
            f"Delay estimated as nk = {res.delay.nk} (equation-error RMS per candidate: {evidence}).",
        ]
    if res.cycles_averaged:
        text += [
            "",
            f"{res.cycles_averaged} whole excitation cycles were averaged before the ARX fit.",
        ]
    return ReportSection(
        heading=f"Motor {m}",
        text="\n".join(text),
        images=[p.relative_to(out_dir) for p in images],
        table=fit_rows(res),
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
    return write_summary(out, title="Motor identification", sections=sections)
