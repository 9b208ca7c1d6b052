"""The commissioning stages that drive the plant or write files.

Each stage makes its own plant from the name, so a serial cart is connected for its experiment
and closed (zero volts) at its end; an experiment stopped by Ctrl-C or a plant fault keeps its
ticks (:func:`cartctl.runtime.loop.run_experiment`)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from cartctl import stopping
from cartctl.cart import PERIOD_S
from cartctl.cli.progress import ProgressBar
from cartctl.commission import StageError, checks, report, tuning
from cartctl.data.modelfile import save_models
from cartctl.data.outputs import writing
from cartctl.data.trace import Trace, meta_path, write_trace, write_trace_meta
from cartctl.identification.pipeline import model_file
from cartctl.plants.base import ClockedPlant
from cartctl.plants.factory import PLANTS_USING, SIMULATED, make_plant, plant_kind
from cartctl.runtime.loop import run_experiment
from cartctl.runtime.realtime import one_blas_thread
from cartctl.signals import make_signal
from cartctl.sinks.csv_sink import CsvSink
from cartctl.tune.engine import save_setting

STAGES = ("checks", "excitation", "identification", "tuning", "verification")
# ``cartctl run``'s plant options, by their key in ``Commission.plant_options``
PLANT_FLAGS = {
    "--preset": "preset",
    "--noise": "noise_std_rad_s",
    "--connect-timeout": "connect_timeout_s",
    "--seed": "seed",
}


class StageStoppedError(Exception):
    """An experiment ended early (Ctrl-C or a plant fault); what was recorded is kept."""

    def __init__(self, stage: str, failure: str | None) -> None:
        super().__init__(stage)
        self.stage, self.failure = stage, failure


@dataclass
class Commission:
    """Commissioning of the plant ``spec`` into ``out``, one method per stage. ``plant_options`` go
    to ``make_plant``; ``jobs`` are the tuning's worker processes; ``run_command`` runs ``cartctl
    run`` with the given arguments and returns its exit code and ``--json`` summary (injected by the
    command, which owns the CLI); ``results`` collects each finished stage's figures for
    ``--json``."""

    spec: str
    out: Path
    plant_options: dict[str, Any]
    run_command: Callable[[list[str]], tuple[int, dict[str, Any] | None]]
    jobs: int | None = None
    results: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.report = report.Report(self.out / "summary.md", f"cartctl commission {self.spec}")
        self.description = self.spec
        self.loop_delay_ticks = 1
        self.amplitude: checks.Amplitude | None = None
        self.excitation: Trace | None = None
        self.model_path = self.out / "model.toml"
        self.controller_path = self.out / "controller.toml"
        self.tuned: tuning.TuningResult | None = None
        self.current = STAGES[0]

    def say(self, stage: str, text: str) -> None:
        """Progress on stderr: '[2/5] excitation: …'."""
        step = f"[{STAGES.index(stage) + 1}/{len(STAGES)}]"
        print(f"cartctl commission {step} {stage}: {text}", file=sys.stderr, flush=True)

    def _done(self, stage: str, series: Any, body: str, failure: StageError | None = None, *,
              layout: bool = False) -> None:  # fmt: skip
        """Record the stage, write its section (with why it stopped) and raise ``failure``."""
        problem = report.record_stage(self.out / f"{stage}.rrd", series, body, stage, layout=layout)
        if problem:
            self.problems.append(problem)
        self.report.add(stage, body + (f"\n\n**Stopped:** {failure}" if failure else ""))
        if failure is not None:
            raise failure

    def _experiment(self, stage: str, ua: np.ndarray, ub: np.ndarray, probe: bool = False) -> Trace:
        """Send ``ua``, ``ub`` (V) to a new plant; keep the trace as <stage>.csv, even if cut short."""
        plant, self.description = make_plant(self.spec, **self.plant_options)
        try:
            if isinstance(plant, ClockedPlant):
                plant.connect()  # the port and the cart's HEARTBEAT, or one clear line
                if probe:
                    self.loop_delay_ticks = int(plant.measure_loop_delay())  # type: ignore[attr-defined]
                    spread = getattr(plant, "probe_delays", None)
                    if spread is not None and not spread.clear:  # a controller is for one loop
                        raise StageError(
                            f"checks: the loop delay is not clear ({spread.describe()}): the PC "
                            "answers the cart late now and then; close what else runs (or "
                            "use a less busy machine) and commission again"
                        )
            elif probe:
                self.loop_delay_ticks = int(getattr(plant, "loop_delay_ticks", 1) or 1)
        except BaseException:
            plant.close()
            raise
        bar, path = ProgressBar(ua.size, f"cartctl commission {stage}"), self.out / f"{stage}.csv"
        opened: list[tuple[str, ...]] = []

        def meta(columns: Sequence[str]) -> None:  # from the first row: a cut trace has its loop
            opened.append(tuple(columns))
            with writing(meta_path(path)):  # a full disk: a fault naming the file, as the trace's
                write_trace_meta(path, plant=self.description, command=f"cartctl commission "
                                 f"{self.spec}", loop_delay_ticks=self.loop_delay_ticks)  # fmt: skip

        flush_every = 50 if isinstance(plant, ClockedPlant) else 1000  # run's
        sink = CsvSink(path, flush_every=flush_every, on_open=meta)
        try:
            result = run_experiment(
                plant, ua, ub, on_tick=bar.update, source=self.description, sink=sink
            )
        finally:
            bar.close()
        with stopping.deferred():  # the experiment is over: a stop signal waits for its trace
            if len(result.trace) and tuple(result.trace.columns()) != opened[0]:  # true speeds cut
                write_trace(result.trace, path)
        if result.interrupted or result.failure or stopping.received() is not None:
            self.report.add(stage, f"**Stopped** after {len(result.trace)} ticks: "
                                   f"{result.failure or 'interrupted'}; {stage}.csv holds them.")  # fmt: skip
            raise StageStoppedError(stage, result.failure)
        return result.trace

    def run_checks(self) -> None:
        """Stage 1: port, heartbeat, loop delay; direction, encoder sign, breakaway; amplitude."""
        self.say("checks", "connecting, then a pulse and a slow ramp on each motor (5.5 s)")
        ua, ub, windows = checks.checks_sequence(PERIOD_S)
        trace = self._experiment("checks", ua, ub, probe=True)
        found = checks.analyse_checks(trace, windows, self.loop_delay_ticks)
        failure = None
        try:
            checks.verdict(found)
            self.amplitude = checks.choose_amplitude(found, checks.STEP_RAD_S)
        except StageError as exc:
            failure = exc
        body = report.checks_body(self.loop_delay_ticks, found, self.description, self.amplitude)
        report.plot_lines(self.out / "checks.png", "Checks: pulses, then ramps", [
            ("voltage (V)", {f"motor {m}": (trace.time_s, trace.voltage(m)) for m in "ab"}),
            ("speed (rad/s)", {f"motor {m}": (trace.time_s, trace.speed(m)) for m in "ab"})])  # fmt: skip
        self.results["checks"] = {"plant": self.description,
                                  "loop_delay_ticks": self.loop_delay_ticks,
                                  "motors": {m: c.to_dict() for m, c in found.items()},
                                  "amplitude_v": None if self.amplitude is None
                                  else self.amplitude.voltage_v}  # fmt: skip
        self._done("checks", report.trace_series(trace), body, failure, layout=True)
        self.say("checks", f"loop delay {self.loop_delay_ticks} tick(s); breakaway "
                 + ", ".join(f"{m} {c.breakaway_v:.2f} V" for m, c in found.items())
                 + f"; excitation {self.amplitude.voltage_v:g} V")  # type: ignore[union-attr]  # fmt: skip

    def run_excitation(self) -> None:
        """Stage 2: the report's square wave at the chosen amplitude on both motors."""
        assert self.amplitude is not None
        volts = make_signal("square", self.amplitude.voltage_v)
        self.say("excitation", f"square ±{self.amplitude.voltage_v:g} V, {volts.size / 100:g} s")
        trace = self.excitation = self._experiment("excitation", volts, volts)
        body = (f"The report's square wave (+A, 0, −A for 1 s each, 5 cycles) at A = "
                f"{self.amplitude.voltage_v:g} V on both motors; peak speeds "
                + ", ".join(f"{m} {np.max(np.abs(trace.speed(m))):.1f} rad/s" for m in "ab")
                + ".\n\nFiles: excitation.csv, excitation.rrd.")  # fmt: skip
        self.results["excitation"] = {"amplitude_v": self.amplitude.voltage_v, "ticks": len(trace),
                                      "trace": str(self.out / "excitation.csv")}  # fmt: skip
        self._done("excitation", report.trace_series(trace), body, layout=True)

    def run_identification(self) -> None:
        """Stage 3: ARX with a validation split; the verdict; model.toml (model-failed.toml)."""
        assert self.excitation is not None and self.amplitude is not None
        self.say("identification", f"ARX na={checks.NA} nb={checks.NB} "
                 f"nk={max(1, self.loop_delay_ticks)}, validated on the last "
                 f"{1 - checks.SPLIT:.0%}")  # fmt: skip
        result, request, verdicts = checks.identify_and_judge(self.excitation,
                                                                  self.loop_delay_ticks)  # fmt: skip
        failure = checks.model_failure(verdicts, self.amplitude.voltage_v)
        if failure is not None:
            self.model_path = self.out / "model-failed.toml"
        files = [str(self.out / "excitation.csv")]
        models = model_file(result, files, request, source=f"cartctl commission {self.spec}")
        save_models(replace(models, loop_delay_ticks=self.loop_delay_ticks), self.model_path)
        body = report.model_body(result, verdicts, self.model_path.name)
        series, panels = {}, []
        for m, r in result.motors.items():
            if not r.diagnostics.validation:
                continue
            y, u = (np.asarray(part, dtype=np.float64) for part in r.diagnostics.validation[0])
            t = np.arange(y.size, dtype=np.float64) * result.period_s
            sim = r.chosen.model.simulate(u)
            series[f"identification/{m}/measured"] = (t, y)
            series[f"identification/{m}/simulated"] = (t, sim)
            panels.append((f"motor {m} (rad/s)", {"measured": (t, y), "model": (t, sim)}))
        if panels:
            report.plot_lines(self.out / "identification.png",
                              "Validation: measured speed and the model's simulation", panels)  # fmt: skip
        self.results["model"] = {
            "path": str(self.model_path), "passed": failure is None, "loop_delay_ticks": self.loop_delay_ticks,
            "motors": {m: {"theta": list(r.chosen.model.theta), "nk": r.chosen.model.nk,
                           "dc_gain": r.chosen.model.dc_gain(), **verdicts[m].to_dict()}
                       for m, r in result.motors.items()}}  # fmt: skip
        self._done("identification", series, body, failure)

    def run_tuning(self) -> None:
        """Stage 4: the robust grid on the model; controller.toml."""
        self.say("tuning", f"{tuning.GRID}: each on the model, {tuning.PLANTS} plants of its "
                 "uncertainty and commands landing 2 and 4 ms later")  # fmt: skip
        bar = ProgressBar(len(tuning.SETTINGS), "cartctl commission tuning")
        try:
            self.tuned = tuning.run_tuning(self.model_path, self.loop_delay_ticks, bar.update,
                                           self.jobs)  # fmt: skip
        except StageError as exc:
            self.report.add("tuning", f"**Stopped:** {exc}")
            raise
        finally:
            bar.close()
        command = save_setting(tuning.METHOD, self.tuned.chosen.result.settings, self.model_path,
                               self.controller_path, fixed=self.tuned.design_fixed)  # fmt: skip
        chosen = tuning.row_summary(self.tuned.chosen)
        body = report.tuning_body(self.tuned, command)
        series = report.tuning_steps(self.controller_path, self.model_path,
                                     self.out / "tuning.png")  # fmt: skip
        self.results["controller"] = {"path": str(self.controller_path), "command": command,
                                      "settings": chosen["settings"],
                                      "predicted": self.tuned.predicted(),
                                      "timing_plants": chosen.get("timing")}  # fmt: skip
        self._done("tuning", series, body)

    def run_verification(self) -> None:
        """Stage 5: ``cartctl run`` of the controller on the plant; measured against predicted."""
        assert self.tuned is not None
        kind, opts = plant_kind(self.spec), self.plant_options
        fast = kind in SIMULATED
        self.say("verification", f"{checks.REFERENCE} for {checks.DURATION_S:g} s with "
                 f"controller.toml{' (--fast)' if fast else ''}")  # fmt: skip
        plant_options = [
            a
            for f, k in PLANT_FLAGS.items()
            if opts[k] is not None and kind in PLANTS_USING[f]
            for a in (f, str(opts[k]))
        ]
        argv = checks.run_argv(
            self.spec, self.controller_path, self.out, fast=fast, plant_options=plant_options
        )
        code, summary = self.run_command(argv)
        if summary is None or code not in (0,):
            self.report.add("verification", f"`cartctl {' '.join(argv)}` ended with code {code}.")
            if code >= 128:
                raise StageStoppedError("verification", None)
            raise StageError(f"verification: the closed-loop run ended with code {code}; see "
                              f"{self.out / 'verification.csv'}")  # fmt: skip
        # run's figures on the RTS-smoothed speed (compare takes them where there is no true speed)
        smoothed = {m: f["smoothed"] for m, f in (summary.get("motors") or {}).items()
                    if isinstance(f.get("smoothed"), dict)} or None  # fmt: skip
        checked = checks.compare(summary, self.tuned.predicted(), smoothed)
        self.results["verification"] = {**checked.to_dict(), "trace": summary.get("trace"),
                                         "recording": summary.get("recording"),
                                         "command": "cartctl " + " ".join(argv)}  # fmt: skip
        body = report.verification_body(checked, summary, argv)
        self.report.add("verification", body)
        if not checked.passed:
            raise StageError(f"verification: the step on the cart missed its bounds: "
                             f"{report.missed_bounds(checked)}; see summary.md")  # fmt: skip

    def run_all(self) -> None:
        """Every stage in order, on one BLAS thread: the matrices are a few states wide, and more
        threads only spin (a third of the CPU on two cores), as in the tuning's workers."""
        with one_blas_thread():
            for stage in STAGES:
                self.current = stage
                getattr(self, f"run_{stage}")()
