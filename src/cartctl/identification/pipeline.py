"""``cartctl identify``'s pipeline, traces in and one result per motor out: the experiments that
drive the motor, optionally averaged over whole cycles and prefiltered (then also fitted without
the filter), the delay (given, or estimated jointly for both motors), ARX and optionally its
output-error refinement. Simulation fits are on the raw data, so every variant compares alike."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from cartctl.choices import as_float, is_number, is_whole
from cartctl.data.modelfile import ModelFile, Provenance
from cartctl.data.trace import Trace
from cartctl.errors import InputError
from cartctl.identification.arx import ArxFit, Segment, check_orders, first_row, fit_arx
from cartctl.identification.diagnostics import Diagnostics, diagnose
from cartctl.identification.etfe import average_cycles, find_period, periodic_regression_pad
from cartctl.identification.oe import check_oe_orders, fit_oe
from cartctl.identification.orders import (
    DelayEstimate,
    JointDelay,
    delay_evidence,
    joint_delay,
    order_table,
)

METHODS = ("arx", "oe")

MIN_PART = 50  # fewest samples an estimation or validation part of a ``--split`` may have


@dataclass(frozen=True)
class Prefilter:
    """The report's Butterworth prefilter (§3.2): one low-pass of ``order`` (1..12) with its −3 dB
    point at ``cutoff_hz`` (Hz) on input and output before the fit, which keeps their ratio, the
    transfer function, in the pass band. The report: 6th order at 20 Hz, causal (MATLAB's
    ``filter``); ``zero_phase`` runs it forward and backward (no lag, squared magnitude)."""

    order: int = 6
    cutoff_hz: float = 20.0
    zero_phase: bool = False

    def __post_init__(self) -> None:
        if not is_whole(self.order) or not 1 <= self.order <= 12:
            raise InputError(
                f"prefilter order (--order) must be a whole number in 1..12, got {self.order!r}"
            )
        if not is_number(self.cutoff_hz):
            raise InputError(
                f"prefilter cut-off (--cutoff-hz) must be a number, got {self.cutoff_hz!r}"
            )
        cutoff = as_float(self.cutoff_hz)
        if math.isnan(cutoff):
            raise InputError("prefilter cut-off (--cutoff-hz) must be a number, got nan")
        if not (math.isfinite(cutoff) and cutoff > 0.0):
            raise InputError(
                "prefilter cut-off (--cutoff-hz) must be a positive, finite frequency in Hz, got "
                f"{cutoff:g}"
            )

    def _sos(self, period_s: float) -> NDArray[np.float64]:
        nyquist_hz = 0.5 / period_s
        if self.cutoff_hz >= nyquist_hz:
            raise InputError(
                f"prefilter cut-off (--cutoff-hz) {self.cutoff_hz:g} Hz must lie below the Nyquist frequency "
                f"{nyquist_hz:g} Hz"
            )
        return signal.butter(self.order, self.cutoff_hz, fs=1.0 / period_s, output="sos")

    def apply(self, x: ArrayLike, period_s: float) -> NDArray[np.float64]:
        """Filter one signal (one value per tick of ``period_s`` s), starting from rest."""
        sos, arr = self._sos(period_s), np.asarray(x, dtype=float)
        return signal.sosfiltfilt(sos, arr) if self.zero_phase else signal.sosfilt(sos, arr)

    def apply_periodic(self, cycle: ArrayLike, period_s: float) -> NDArray[np.float64]:
        """Filter one cycle of a periodic signal: the filter's periodic steady state (no start
        from rest), exact on the cycle's DFT bins; zero-phase multiplies by |H|² instead of H."""
        x = np.asarray(cycle, dtype=float)
        w_rad = 2.0 * np.pi * np.fft.rfftfreq(x.size)
        h = signal.sosfreqz(self._sos(period_s), worN=w_rad)[1]
        return np.fft.irfft(np.fft.rfft(x) * (np.abs(h) ** 2 if self.zero_phase else h), n=x.size)

    def describe(self) -> str:
        """For provenance and tables, e.g. 'butter order 6, 20 Hz, causal'."""
        kind = "zero-phase" if self.zero_phase else "causal"
        return f"butter order {self.order}, {self.cutoff_hz:g} Hz, {kind}"


@dataclass(frozen=True)
class IdentifyRequest:
    """The options of ``cartctl identify``: ``delay`` None estimates nk over ``delay_candidates``;
    ``loop_delay_ticks`` (measurement to voltage on the motor) goes into the model file. A motor
    without excitation is an error when named alone, else skipped with a note."""

    motors: tuple[str, ...] = ("a", "b")
    na: int = 2
    nb: int = 2
    delay: int | None = 2
    prefilter: Prefilter | None = None
    method: str = "arx"
    average: bool = False
    delay_candidates: tuple[int, ...] = (1, 2, 3, 4, 5, 6)
    orders: dict[str, tuple[int, ...]] | None = None
    split: float | None = None
    loop_delay_ticks: int | None = None

    def __post_init__(self) -> None:
        ticks = self.loop_delay_ticks  # whole: the model file keeps int(ticks)
        if ticks is not None and not (is_whole(ticks) and 0 <= ticks <= 50):
            raise InputError(f"--loop-delay must be in 0..50 ticks, got {self.loop_delay_ticks}")
        if self.method not in METHODS:
            raise InputError(f"unknown method '{self.method}'; choose one of {', '.join(METHODS)}")
        check_orders(self.na, self.nb, 0 if self.delay is None else self.delay)  # before the data
        if self.method == "oe":
            check_oe_orders(self.na, self.nb)
        if not self.motors or any(m not in ("a", "b") for m in self.motors):
            raise InputError(f"motors must be 'a' and/or 'b', got {list(self.motors)}")


@dataclass(frozen=True)
class MotorIdentification:
    """The result for one motor: the ``chosen`` fit (``method``, prefiltered if asked), the ARX
    fit, its OE refinement (``method='oe'``), ARX without the prefilter (when one was used), the
    motor's delay evidence (``delay.nk`` the joint choice), the cycles averaged, and the
    diagnostics."""

    motor: str
    arx: ArxFit
    diagnostics: Diagnostics
    oe: ArxFit | None = None
    unfiltered: ArxFit | None = None
    delay: DelayEstimate | None = None
    cycles_averaged: int | None = None

    @property
    def chosen(self) -> ArxFit:
        """The fit of the requested method: the OE refinement if made, else ARX."""
        return self.oe or self.arx

    def variants(self) -> dict[str, ArxFit]:
        """Every fit made, by label, for tables and plots."""
        out = {"ARX": self.arx}
        if self.unfiltered is not None:
            out = {"ARX, unfiltered": self.unfiltered, "ARX, prefiltered": self.arx}
        return out | ({} if self.oe is None else {"OE": self.oe})

    def to_dict(self) -> dict[str, Any]:
        fits = {"arx": self.arx, "oe": self.oe} if self.oe is not None else {}
        fits |= {} if self.unfiltered is None else {"unfiltered": self.unfiltered}
        out = self.chosen.to_dict() | {k: fit.to_dict() for k, fit in fits.items()}
        out["delay_estimate"] = None if self.delay is None else self.delay.to_dict()
        return out | {"cycles_averaged": self.cycles_averaged} | self.diagnostics.to_dict()


@dataclass(frozen=True)
class IdentifyResult:
    """Per motor results, notes for the user (skipped motors, a close delay call), the joint
    delay when it was estimated, and the loop delay the data was recorded in."""

    period_s: float
    motors: dict[str, MotorIdentification]
    notes: tuple[str, ...] = field(default=())
    delay: JointDelay | None = None
    loop_delay_ticks: int | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"Ts": self.period_s}
        out["motors"] = {m: r.to_dict() for m, r in self.motors.items()}
        out["delay"] = None if self.delay is None else self.delay.to_dict()
        return out | {"loop_delay_ticks": self.loop_delay_ticks}


def _no_excitation(traces: Sequence[Trace], motor: str) -> str | None:
    """Why ``motor``'s voltage cannot identify anything (zero or one constant throughout), or None."""
    volts = np.concatenate([t.voltage(motor) for t in traces])
    if not np.any(volts != 0.0):
        return "its voltage is zero throughout"
    if np.ptp(volts) == 0.0:
        return f"its voltage is a constant {float(volts[0]):g} V throughout"
    return None


def _segments(traces: Sequence[Trace], motor: str) -> list[Segment]:
    return [(t.speed(motor), t.voltage(motor)) for t in traces if np.any(t.voltage(motor) != 0.0)]


def _averaged(
    segments: Sequence[Segment],
    lags: int,
    sources: Sequence[str],
    prefilter: Prefilter | None = None,
    period_s: float = 0.0,
) -> tuple[list[Segment], int]:
    """The raw experiments' whole cycles averaged (the period found on the raw input, which a
    prefilter's transient would hide), then prefiltered as periodic signals."""
    out: list[Segment] = []
    total = 0
    for (y, u), src in zip(segments, sources, strict=True):
        period = find_period(u)
        if period is None:
            raise InputError(
                f"--average needs a periodic input with at least two whole cycles; {src}'s is not"
            )
        try:
            y_avg, u_avg, n = average_cycles(y, u, period)
        except InputError as exc:  # too few cycles: name the option and the file
            raise InputError(f"--average on {src}: {exc}") from None
        if prefilter is not None:
            y_avg, u_avg = (prefilter.apply_periodic(x, period_s) for x in (y_avg, u_avg))
        out.append(periodic_regression_pad(y_avg, u_avg, lags))
        total += n
    return out, total


def split_segments(
    segments: Sequence[Segment], fraction: float
) -> tuple[list[Segment], list[Segment]]:
    """Split each experiment: the first ``fraction`` of its samples estimate, the rest validate
    (each part at least :data:`MIN_PART` samples)."""
    if not 0.0 < fraction < 1.0:
        raise InputError(f"--split must be a fraction between 0 and 1 (e.g. 0.7), got {fraction:g}")
    est: list[Segment] = []
    val: list[Segment] = []
    for y_like, u_like in segments:
        y, u = np.asarray(y_like), np.asarray(u_like)
        n = len(y)
        m = round(fraction * n)
        if min(m, n - m) < MIN_PART:
            raise InputError(
                f"--split {fraction:g} leaves {m} estimation and {n - m} validation samples of "
                f"{n}; each part needs at least {MIN_PART}"
            )
        est.append((y[:m], u[:m]))
        val.append((y[m:], u[m:]))
    return est, val


def _identify_motor(
    motor: str,
    raw: list[Segment],
    work: list[Segment],
    sources: list[str],
    validation: list[Segment],
    request: IdentifyRequest,
    nk: int,
    period_s: float,
    delay: DelayEstimate | None,
) -> MotorIdentification:
    """The pipeline on one motor's raw experiments, the same prefiltered (``work``), their files
    and the validation data, with delay ``nk``; with validation data the fits are on it."""
    na, nb = request.na, request.nb
    fit_data, start, cycles = work, None, None
    if request.average:
        start = first_row(na, nb, nk)
        fit_data, cycles = _averaged(raw, start, sources, request.prefilter, period_s)
    arx = partial(fit_arx, na=na, nb=nb, nk=nk, period_s=period_s, start=start, eval_segments=raw)
    arx_fit = arx(fit_data)
    unfiltered = None
    if request.prefilter is not None:
        unfiltered = arx(raw if start is None else _averaged(raw, start, sources)[0])
    oe_fit = fit_oe(work, arx_fit.model, eval_segments=raw) if request.method == "oe" else None
    if oe_fit is not None and request.average:  # it simulates from rest; an averaged cycle is not
        note = (
            "--average: refined on the raw experiments (its simulation starts from rest, an "
            "averaged cycle does not); the averaged cycles gave its ARX start"
        )
        oe_fit = dataclasses.replace(oe_fit, notes=(note, *oe_fit.notes))
    diagnostics = diagnose(oe_fit or arx_fit, raw, validation, None)
    if request.orders is not None:  # after the residual tests, which refuse too few samples
        table_data = work
        if request.average:  # the same averaged cycles, padded for the grid's longest lags
            lags = first_row(*(max(request.orders[k]) for k in ("na", "nb", "nk")))
            table_data = _averaged(raw, lags, sources, request.prefilter, period_s)[0]
        orders = order_table(
            table_data, request.orders, period_s=period_s, eval_segments=raw, validation=validation
        )
        diagnostics = dataclasses.replace(diagnostics, orders=orders)
    if validation:
        arx_fit = arx_fit.on(validation)
        oe_fit = oe_fit.on(validation) if oe_fit else None
        unfiltered = unfiltered.on(validation) if unfiltered else None
    return MotorIdentification(motor, arx_fit, diagnostics, oe_fit, unfiltered, delay, cycles)


def identify(
    traces: Sequence[Trace], request: IdentifyRequest, validation: Sequence[Trace] = ()
) -> IdentifyResult:
    """Identify the requested motors from the traces (validated on ``validation``, if any);
    refuses traces with different ticks, a motor named alone that no trace excites, and no motor
    excited at all."""
    if not traces:
        raise InputError("no traces to identify from")
    period_s = round(traces[0].period_s, 9)
    for t in [*traces[1:], *validation]:
        if abs(t.period_s - period_s) > 1e-6:
            raise InputError(
                f"traces have different sample periods: {period_s} s ({traces[0].source}) and "
                f"{t.period_s} s ({t.source})"
            )
    data: dict[str, tuple[list[Segment], list[str], list[Segment]]] = {}
    notes: list[str] = []
    problems: list[str] = []
    names = ", ".join(str(t.source) for t in traces)
    for motor in request.motors:
        problem = _no_excitation(traces, motor)
        if problem is not None:
            if len(request.motors) == 1:
                raise InputError(
                    f"motor {motor} has no excitation: {problem} in {names}; nothing to identify"
                )
            notes.append(f"motor {motor} skipped: no excitation ({problem})")
            problems.append(f"motor {motor}: {problem}")
            continue
        segments = _segments(traces, motor)
        sources = [str(t.source) for t in traces if np.any(t.voltage(motor) != 0.0)]
        val = _segments(validation, motor)
        if validation and not val:
            raise InputError(
                f"the validation data ({', '.join(str(t.source) for t in validation)}) has no "
                f"excitation on motor {motor}; validate on an experiment that drives it"
            )
        if request.split is not None:
            segments, val = split_segments(segments, request.split)
        data[motor] = (segments, sources, val)
    if not data:
        raise InputError(
            f"no motor has excitation in {names} ({'; '.join(problems)}); record with a varying "
            "voltage, e.g. cartctl excite --signal square"
        )
    pf = request.prefilter
    work: dict[str, list[Segment]] = {
        m: [(pf.apply(y, period_s), pf.apply(u, period_s)) for y, u in raw] if pf else raw
        for m, (raw, _, _) in data.items()
    }
    joint, nk = None, request.delay
    if nk is None:  # one loop, one delay: chosen from both motors' evidence, on the fit's data
        evidence = partial(delay_evidence, na=request.na, nb=request.nb, period_s=period_s)
        cands = request.delay_candidates
        lags = max((first_row(request.na, request.nb, c) for c in cands), default=0)
        joint = joint_delay({
            m: evidence(_averaged(raw, lags, src, pf, period_s)[0] if request.average else work[m],
                        candidates=cands, eval_segments=raw)
            for m, (raw, src, _) in data.items()
        })  # fmt: skip
        nk = joint.nk
        if (note := joint.note()) is not None:
            notes.append(note)
    results = {
        m: _identify_motor(
            m, raw, work[m], src, val, request, nk, period_s, joint.motors[m] if joint else None
        )
        for m, (raw, src, val) in data.items()
    }
    return IdentifyResult(period_s, results, tuple(notes), joint, request.loop_delay_ticks)


def model_file(
    result: IdentifyResult,
    files: Sequence[str],
    request: IdentifyRequest,
    *,
    source: str = "cartctl identify",
) -> ModelFile:
    """The chosen models with their provenance (``source``: the command line or the Python call)
    and figures, ready to save (``identify --out``)."""
    notes = []
    if (j := result.delay) is not None:
        joint = " for both motors, from their joint evidence" if len(j.motors) > 1 else ""
        close = f" (too close to call: {', '.join(map(str, j.close))})" if j.too_close else ""
        notes.append(f"delay nk = {j.nk} estimated over {list(j.candidates)}{joint}{close}")
    for m, r in result.motors.items():
        if r.cycles_averaged:
            notes.append(f"motor {m}: {r.cycles_averaged} cycles averaged")
        if r.diagnostics.fit_on == "validation":
            notes.append(f"motor {m}: fits on validation data")
    provenance = Provenance(
        source=source,
        created=datetime.now(UTC).isoformat(timespec="seconds"),
        data=tuple(files),
        method=request.method,
        prefilter=request.prefilter.describe() if request.prefilter else "none",
        notes="; ".join(notes),
    )
    keys = ("theta_std", "fit_simulation_percent", "fit_prediction_percent")
    dicts = {m: r.chosen.to_dict() for m, r in result.motors.items()}
    stats = {m: {k: d[k] for k in keys if d[k] is not None} for m, d in dicts.items()}
    models = {m: r.chosen.model for m, r in result.motors.items()}
    return ModelFile(models, provenance, stats, loop_delay_ticks=result.loop_delay_ticks)
