"""``cartctl run``: the closed loop against a plant, in real time or as fast as possible (``--fast``)."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cartctl.cli.commands.options as options
from cartctl import stopping
from cartctl.cart import check_voltage_limit
from cartctl.errors import InputError, OutputError, PlantError
from cartctl.session.prepare import DEFAULT_CONTROLLER

if TYPE_CHECKING:
    from cartctl.runtime.loop import ControlLoop, MemorySink
    from cartctl.session.prepare import PreparedRun


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run the 10 ms closed loop against a plant",
        description="Run the designed controller every 10 ms against a plant, record the trace "
        "(CSV) and a Rerun recording to --out, and print a summary. With no options: the shipped "
        "PI controller on the simulated ground model, a 10 rad/s step, 5 s in real time.",
    )
    options.add_plant_options(p, what="what to control")
    p.add_argument(
        "--controller",
        metavar="CONTROLLER.toml",
        help=f"controller file (default {DEFAULT_CONTROLLER}, on every plant: the serial loop "
        "has the on-board loop delay of 1 tick)",
    )
    p.add_argument(
        "--allow-delay-mismatch",
        action="store_true",
        help="run a controller designed for another loop delay than the plant's (a warning "
        "instead of an error)",
    )
    p.add_argument(
        "--allow-unstable",
        action="store_true",
        help="run the sim plant on an unstable model (it stops once a speed runs away)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="run a controller file whose controller_num/controller_den disagree with its gains "
        "(the gains run; a warning says what is ignored)",
    )
    p.add_argument(
        "--reference",
        default="step:10",
        metavar="SPEC",
        help=f"speed reference of both motors (default step:10): {options.FORMS}",
    )
    p.add_argument("--reference-b", metavar="SPEC", help="a different reference for motor b")
    p.add_argument(
        "--duration", type=float, default=5.0, metavar="S", help="run time (default 5 s)"
    )
    p.add_argument(
        "--fast",
        action="store_true",
        help="run on a simulated clock, as fast as the CPU allows (simulated plants)",
    )
    options.add_rerun_options(p)
    options.add_output_options(p, name_default="run-DATE-TIME")
    p.add_argument(
        "--voltage-limit",
        type=float,
        metavar="V",
        help="a lower voltage limit than the controller file's (at most 12 V): the controllers, "
        "their anti-windup and estimators work with it",
    )
    options.add_json_option(p, "print the summary as one JSON object (keys: docs/architecture.md)")
    p.set_defaults(func=run, say_stopped=True)  # commission's in-process run: it says so itself


def _checked_outputs(args: argparse.Namespace) -> tuple[Path, Path]:
    """Step 1, the refusals that need nothing loaded or driven; the trace and recording paths."""
    options.check_duration(args.duration)
    if args.voltage_limit is not None:
        limit = options.check_finite(args.voltage_limit, "--voltage-limit")
        check_voltage_limit(limit, "--voltage-limit")
    from cartctl.plants.factory import SIMULATED, check_plant_name
    from cartctl.reference import check_reference

    kind = check_plant_name(args.plant)  # first: what is checked next depends on the plant
    options.check_plant_options(args)
    check_reference(args.reference, "--reference")
    if args.reference_b:
        check_reference(args.reference_b, "--reference-b")
    files = [spec[5:] for spec in (args.reference, args.reference_b or "") if spec[:5] == "file:"]
    csv_path, rrd_path = options.check_run_outputs(args, "run", inputs=tuple(files))
    if args.fast and kind not in SIMULATED:
        raise InputError(f"--fast needs a simulated plant (sim or physics), not '{args.plant}'")
    return csv_path, rrd_path


def _prepared(args: argparse.Namespace, given: str) -> PreparedRun:
    """Step 2, the session's run path (controller, plant, references, every refusal)."""
    from cartctl.session.prepare import prepare_run

    def warm_up_rerun() -> None:  # the recording's first-use costs, before a cart ticks
        if args.rerun != "off" and not args.fast:
            from cartctl.sinks.rerun_sink import warm_up

            warm_up()

    return prepare_run(
        given, given=given, plant=args.plant, duration_s=args.duration, reference=args.reference,
        reference_b=args.reference_b, model=args.model, preset=args.preset,
        noise_std_rad_s=args.noise, seed=args.seed, connect_timeout_s=args.connect_timeout,
        voltage_limit_v=args.voltage_limit, force=args.force, allow_unstable=args.allow_unstable,
        allow_delay_mismatch=args.allow_delay_mismatch, before_plant=warm_up_rerun,
    )  # fmt: skip


def _sinks(
    args: argparse.Namespace, prepared: PreparedRun, given: str, csv_path: Path, rrd_path: Path
) -> tuple[list[Any], MemorySink, Any]:
    """Step 3, where the rows go: the trace (and its meta file, written with its header: a run
    stopped before its first tick leaves an earlier run's files of its name as they were),
    memory (for the summary), the recording (or None), a status line on a terminal."""
    from cartctl.choices import find_file
    from cartctl.data.trace import write_trace_meta
    from cartctl.runtime.loop import MemorySink
    from cartctl.sinks.csv_sink import CsvSink

    def write_meta(_columns: object) -> None:
        try:
            write_trace_meta(csv_path, plant=prepared.description,
                             loop_delay_ticks=prepared.loop_delay_ticks,
                             command=options.command_line("run"),
                             controller=prepared.controller_file.path or find_file(given),
                             model=find_file(prepared.controller_file.model_path))  # fmt: skip
            if args.rerun == "off":  # an earlier run's of this name would pass for this one's
                rrd_path.unlink(missing_ok=True)
        except OSError as exc:  # a full disk
            raise OutputError(exc.filename or csv_path, exc.strerror or str(exc)) from None

    memory = MemorySink()
    # on the simulated clock a second of trace takes milliseconds: write it in bigger blocks
    trace = CsvSink(csv_path, flush_every=1000 if args.fast else 50, on_open=write_meta)
    sinks: list[Any] = [trace, memory]
    rerun = None
    if args.rerun != "off":
        from cartctl.sinks.rerun_layout import run_ranges
        from cartctl.sinks.rerun_problems import resolve_mode
        from cartctl.sinks.rerun_sink import HeldRerunSink  # open for the smoothed speed

        extremes = {}  # each reference's lowest and highest value: the speed plots' ranges
        for m, ref in prepared.references.items():
            spans = [(float(c.min()), float(c.max())) for c in ref.chunks() if c.size]
            extremes[m] = (min((lo for lo, _ in spans), default=0.0),
                           max((hi for _, hi in spans), default=0.0))  # fmt: skip
        # one send_columns costs ~170 µs whatever its length: batch 20 ticks live (the SDK
        # flushes every 200 ms anyway), 1000 on the simulated clock
        rerun = HeldRerunSink(
            resolve_mode(args.rerun),
            rrd_path,
            connect_url=args.connect_url,
            batch_ticks=1000 if args.fast else 20,
            ranges=run_ranges(extremes, prepared.voltage_limit_v),
        )
        sinks.append(rerun)
    if not args.fast and sys.stderr.isatty():  # a live line on a terminal, refreshed after ticks
        from cartctl.sinks.summary import StatusLine

        sinks.append(StatusLine(sys.stderr, period_s=prepared.period_s))
    return sinks, memory, rerun


def _run_loop(
    args: argparse.Namespace, prepared: PreparedRun, sinks: list[Any], after: contextlib.ExitStack
) -> tuple[ControlLoop, dict[str, Any], str]:
    """Step 4, the loop until the last tick, a signal or a fault (zero volts whatever happens);
    the loop (its ``state`` says how it ended), the timing figures and the scheduling. From the
    loop's end until ``after`` closes, a stop signal is only noted."""
    from cartctl.plants.base import ClockedPlant
    from cartctl.runtime.executor import (
        BackToBackExecutor,
        CartClockedExecutor,
        MonotonicClock,
        PeriodicExecutor,
        SimulatedClock,
    )
    from cartctl.runtime.loop import ControlLoop
    from cartctl.runtime.realtime import enable_realtime, gc_paused, restore

    plant, period_s, n = prepared.plant, prepared.period_s, prepared.ticks
    clock = SimulatedClock() if args.fast else MonotonicClock()
    loop = ControlLoop(plant, prepared.controllers, prepared.references, sinks,
                       now_s=clock.now_s, voltage_limit_v=prepared.voltage_limit_v,
                       period_s=period_s)  # fmt: skip
    executor: Any
    if clocked := isinstance(plant, ClockedPlant):
        executor = CartClockedExecutor(plant, max_ticks=n, now_s=clock.now_s,
                                       compute_us=lambda: loop.last_compute_us)  # fmt: skip
    elif args.fast:  # ticks back to back: nothing that only real time needs
        executor = BackToBackExecutor(period_s, max_ticks=n)
    else:
        executor = PeriodicExecutor(period_s, clock, max_ticks=n)
    scheduling = "simulated clock (--fast)"
    switch_interval = sys.getswitchinterval()
    stats = None
    try:
        if not args.fast:  # before the start: locking memory takes a while, and a cart ticks on
            scheduling = enable_realtime()
            sys.setswitchinterval(1e-4)  # any other thread hands the GIL back within 0.1 ms,
            # also while loop.finish() sends zero volts (restored after it)

        loop_tick, fast = loop.tick, bool(args.fast)

        def tick(k: int) -> bool:
            if fast:  # every tick on its grid point, on time, in no time
                return loop_tick(k, 0.0, 0.0, k * period_s)
            time_s = executor.time_s if clocked else executor.grid_index * period_s
            return loop_tick(k, executor.period_error_us, executor.start_s, time_s)

        # no collector pass at a random tick (gc_paused); the simulated clock has no deadline
        with contextlib.nullcontext() if fast else gc_paused():
            loop.start()  # after the one collection: a cart ticks on from its reset
            # a cart-clocked loop calls its idle() itself, while it waits for the cart's frame
            stats = executor.run(tick) if clocked else executor.run(tick, loop.idle)
    except KeyboardInterrupt:  # Ctrl-C, SIGTERM, SIGHUP (cartctl.stopping)
        loop.state.interrupted = True
    except OutputError:  # a file write failed: kept in loop.state.incomplete, a fault
        pass
    except PlantError as exc:
        loop.state.failure = str(exc)
    except Exception as exc:  # a fault of cartctl itself: the motors still get zero volts
        loop.state.failure = f"internal error: {type(exc).__name__}: {exc}"
    finally:  # a second signal must not cut the shutdown short, nor one now the summary
        try:
            after.enter_context(stopping.deferred())
        finally:  # zero volts even for a first signal raised before the deferral began
            loop.finish()
            sys.setswitchinterval(switch_interval)
            if not args.fast:
                restore()
        timing = (stats or executor.stats()).to_dict()
    return loop, timing, scheduling


def _summary(
    prepared: PreparedRun, loop: ControlLoop, memory: MemorySink, rerun: Any,
    timing: dict[str, Any], run_facts: dict[str, Any],
) -> dict[str, Any]:  # fmt: skip
    """Step 5, the run's summary (``--json``'s object)."""
    from cartctl.cli.commands.review.smoothed import smooth_run
    from cartctl.sinks.summary import mark_incomplete, trace_metrics

    summary = trace_metrics(memory.arrays(), prepared.period_s)
    # timing's duration_s is the executor's clock span; the trace's own duration stays
    summary.update({key: value for key, value in timing.items() if key != "duration_s"})
    summary["ticks"] = loop.state.rows  # as the trace and the recording: the stop row included
    link_summary = getattr(prepared.plant, "link_summary", None)
    if link_summary is not None:
        summary.update(link_summary())
    if summary.get("loop_delay_ticks") is None:  # the run's own echoes, else the probe's
        summary["loop_delay_ticks"] = prepared.loop_delay_ticks
    summary.update(controller_loop_delay_ticks=prepared.controller_file.loop_delay_ticks,
                   **run_facts)  # fmt: skip
    try:
        smooth_run(summary, memory.arrays(), prepared.period_s,
                   prepared.controller_file.model_path, rerun)  # fmt: skip
    except OutputError as exc:  # the recording's file, found short when it is closed
        loop.state.output_failed(exc)
    mark_incomplete(summary, loop.state.incomplete)
    return summary


def _report(args: argparse.Namespace, summary: dict[str, Any], loop: ControlLoop) -> int:
    """Step 6, the summary on stdout, warnings and the error line on stderr; the exit code."""
    from cartctl.cli.jsonout import dumps
    from cartctl.sinks.summary import format_summary, warn_delay_change, warn_host_losses

    if args.json:
        print(dumps(summary))
    else:
        print(format_summary(summary))
        print(f"  plant {summary['plant']}; controller {summary['controller']}; "
              f"{summary['scheduling']}")  # fmt: skip
    for problem in loop.state.sink_errors:
        print(f"cartctl run: warning: {problem}", file=sys.stderr)
    warn_host_losses(summary.get("link"), "run")
    warn_delay_change(summary.get("link"), "run")
    return _ended(args, loop, "; zero volts sent, the trace and recording hold the run so far")


def _ended(args: argparse.Namespace, loop: ControlLoop, what: str) -> int:
    """How the run ended, as one line on stderr, and the exit code: the error line (each file and
    why, the failure, the motors), 1; else the stop signal's line (``what`` after its name; left
    to commission when it runs ``run`` in process) and its code; else 0."""
    state = loop.state
    if state.incomplete or state.failure:
        failed = [str(e) for e in state.incomplete] + [state.failure or ""]
        stopped = "; the motors were stopped" if state.incomplete and state.zero_volts_sent else ""
        print(f"cartctl run: error: {'; '.join(f for f in failed if f)}{stopped}", file=sys.stderr)
        return 1
    signum = stopping.received()
    if not state.interrupted and signum is None:  # a signal during the run or after it
        return 0
    why = "interrupted" if signum is None else f"stopped by {signal.Signals(signum).name}"
    if args.say_stopped:
        print(f"cartctl run: {why}{what}", file=sys.stderr)
    return stopping.exit_code()


def run(args: argparse.Namespace) -> int:
    """0, 1 when the run failed (a plant fault, a file left incomplete), or the signal's code."""
    csv_path, rrd_path = _checked_outputs(args)
    given = args.controller or str(DEFAULT_CONTROLLER)  # one file for every plant
    prepared = _prepared(args, given)
    try:  # the loop closes the plant; until it runs, a failure or a stop signal closes it here
        sinks, memory, rerun = _sinks(args, prepared, given, csv_path, rrd_path)
    except BaseException:
        prepared.plant.close()
        raise
    with contextlib.ExitStack() as after:  # a signal after the loop: the summary, then its code
        loop, timing, scheduling = _run_loop(args, prepared, sinks, after)
        if not memory.columns:  # it stopped before the sinks opened (a signal, a plant fault)
            return _ended(args, loop, " before the first tick; zero volts sent, nothing recorded")
        run_facts = {"recording": str(rrd_path) if rerun is not None else None,
                     "trace": str(csv_path), "plant": prepared.description, "controller": given,
                     "scheduling": scheduling}  # fmt: skip
        summary = _summary(prepared, loop, memory, rerun, timing, run_facts)
        return _report(args, summary, loop)
