"""Driving a plant: the closed loop (:class:`ControlLoop`, the per-tick body an executor calls:
docs/architecture.md, "One tick of ``cartctl run``"), and the open-loop experiments of ``cartctl
excite`` (:func:`run_experiment`, paced by the plant). A sink whose file write fails raises
:class:`~cartctl.errors.OutputError` once every other sink has had its row.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.cart import PERIOD_S, SUPPLY_V
from cartctl.data.outputs import call_each
from cartctl.data.trace import REQUIRED_COLUMNS, Trace
from cartctl.errors import InputError, OutputError, PlantError
from cartctl.plants.base import ClockedPlant, Measurement, Plant
from cartctl.plants.sim import saturate
from cartctl.runtime.base import Controller
from cartctl.runtime.executor import BackToBackExecutor, SimulatedClock
from cartctl.sinks.base import TRACE_COLUMNS, TRUE_SPEED_COLUMNS, Sink
from cartctl.stopping import deferred, held


class MemorySink:
    """Keeps every row in memory for the run summary; ``idle`` packs them into float64 blocks (no
    Python tuple kept for long: 1 GB for a 24 h run)."""

    BLOCK_ROWS = 1024

    def __init__(self) -> None:
        self.open(())

    def open(self, columns: Sequence[str]) -> None:
        self.columns = tuple(columns)
        self._blocks: list[NDArray[np.float64]] = []
        self._rows: list[Sequence[float]] = []
        self._block = np.empty((self.BLOCK_ROWS, len(self.columns)))
        self._filled = 0

    def write(self, row: Sequence[float]) -> None:
        rows = self._rows
        rows.append(row)
        if len(rows) >= self.BLOCK_ROWS:  # nobody calls idle(): pack from here
            self.idle()

    def idle(self) -> None:
        rows, self._rows = self._rows, []  # taken first: an interrupt never packs one twice
        for row in rows:
            self._block[self._filled] = row
            self._filled += 1
            if self._filled == self.BLOCK_ROWS:
                self._blocks.append(self._block)
                self._block = np.empty_like(self._block)
                self._filled = 0

    def close(self) -> None:
        pass

    def arrays(self) -> dict[str, NDArray[np.float64]]:
        """The rows as one array per column."""
        self.idle()
        table = np.concatenate([*self._blocks, self._block[: self._filled]])
        return {name: table[:, i] for i, name in enumerate(self.columns)}


@dataclass
class LoopState:
    """What happened, for the summary and the exit code: ``rows`` written (the ticks and the stop
    row) and ``incomplete``, one error per file a failed write left incomplete."""

    rows: int = 0
    interrupted: bool = False
    failure: str | None = None
    zero_volts_sent: bool = False
    sink_errors: list[str] = field(default_factory=list)
    incomplete: list[OutputError] = field(default_factory=list)

    def output_failed(self, error: OutputError) -> None:
        """Keep ``error`` unless its file is already known to be incomplete."""
        if all(e.path != error.path for e in self.incomplete):
            self.incomplete.append(error)


class PerTick(Protocol):
    """A reference (rad/s) per tick: an array, a list or a ReferenceSchedule."""

    def __len__(self) -> int: ...

    def __getitem__(self, k: int, /) -> float: ...


def _per_tick(reference: PerTick | None, n: int) -> PerTick:
    if reference is None:
        return [0.0] * n
    if isinstance(reference, np.ndarray | list | tuple):
        return [float(v) for v in reference]
    return reference


class ControlLoop:
    """The per-tick body of the closed loop over both motors: ``controllers`` and ``references``
    (rad/s per tick, equally long) by motor (none: 0 V); ``now_s`` times each tick's compute;
    ``voltage_limit_v`` clamps every command (a controller's own may be lower)."""

    def __init__(
        self,
        plant: Plant,
        controllers: Mapping[str, Controller],
        references: Mapping[str, PerTick],
        sinks: Sequence[Sink],
        *,
        now_s: Callable[[], float],
        voltage_limit_v: float = SUPPLY_V,
        period_s: float = PERIOD_S,
    ) -> None:
        lengths = {len(r) for r in references.values()}
        if len(lengths) != 1:
            raise InputError(
                "the references of both motors must have one value per tick, equally many"
            )
        self.plant = plant
        self.controllers = dict(controllers)
        n = lengths.pop()
        self.ref_a = _per_tick(references.get("a"), n)
        self.ref_b = _per_tick(references.get("b"), n)
        self.n_ticks = n
        self.sinks = list(sinks)
        self._writers = [s.write for s in self.sinks]
        idlers = (getattr(s, "idle", None) for s in self.sinks)  # a sink may have idle()
        self._idlers = [idle for idle in idlers if callable(idle)]
        self.now_s = now_s
        self.limit = float(voltage_limit_v)
        self.period_s = float(period_s)
        self.state = LoopState()
        self._y: Measurement | None = None
        self._clocked = isinstance(plant, ClockedPlant)  # send, time the compute, then wait
        self.last_compute_us = 0.0
        self._true = False
        self._last_time_s: float | None = None

    def start(self) -> None:
        """Reset the controllers and the plant, open the sinks; a cart-clocked plant last, so that
        the sinks' start-up does not put the loop behind the cart."""
        for c in self.controllers.values():
            c.reset()
        if self._clocked:  # a real cart reports no true speed; the virtual one does
            self._true = bool(getattr(self.plant, "reports_true_speed", False))
        else:
            self._y = self.plant.reset()
            self._true = self._y.true_speed_a_rad_s is not None
        columns = TRACE_COLUMNS + (TRUE_SPEED_COLUMNS if self._true else ())
        with held():  # a stop signal waits for every file's header and a cart's first measurement
            call_each([s.open for s in self.sinks], columns, failed=self.state.output_failed)
            if self._clocked:  # (for the stop row)
                self._y = self.plant.reset()

    def _command(self, motor: str, reference: float, measured: float) -> tuple[float, float]:
        ctrl = self.controllers.get(motor)
        if ctrl is None:
            return 0.0, measured
        return saturate(ctrl.step(reference, measured), self.limit), ctrl.estimate_rad_s

    def tick(
        self, k: int, period_error_us: float, start_s: float, time_s: float | None = None
    ) -> bool:
        """Run tick k (started ``period_error_us`` late, at ``start_s`` on the clock, placed at
        ``time_s`` on the time axis, default k·Ts); False after the last tick."""
        y = self._y
        if y is None:
            raise InputError("ControlLoop.start() must run before the first tick")
        ra, rb, ya, yb = self.ref_a[k], self.ref_b[k], y.speed_a_rad_s, y.speed_b_rad_s
        ua, ea = self._command("a", ra, ya)
        ub, eb = self._command("b", rb, yb)
        t = k * self.period_s if time_s is None else time_s
        row = (t, ua, ub, ya, yb, k, ra, rb, ea, eb, period_error_us)
        if self._clocked:  # send, then log the tick, then wait for the cart's next one
            self.plant.send(ua, ub)  # type: ignore[attr-defined]
            self._log(row, y, start_s)
            self.idle()  # the cart's frame waits in the port meanwhile
            self._y = self.plant.receive()  # type: ignore[attr-defined]
        else:
            self._y = self.plant.step(ua, ub)
            self._log(row, y, start_s)
        return k + 1 < self.n_ticks

    def _log(self, head: tuple[float, ...], y: Measurement, start_s: float) -> None:
        """Write ``head`` with the compute time since ``start_s`` and any true speeds."""
        self.last_compute_us = (self.now_s() - start_s) * 1e6
        row = (*head, self.last_compute_us)
        if self._true:
            row += (y.true_speed_a_rad_s, y.true_speed_b_rad_s)  # type: ignore[operator]
        self.state.rows += 1
        self._last_time_s = row[0]
        call_each(self._writers, row, failed=self.state.output_failed)

    def idle(self) -> None:
        """The sinks' work that need not delay a command, after a tick's compute time is taken."""
        call_each(self._idlers, failed=self.state.output_failed)

    def finish(self) -> None:
        """Zero volts, plant and sinks closed, on every exit path; never raises. The zero-volt
        command, when it went out, is the trace's stop row (tick = rows so far, 0 V, no compute)."""
        try:  # a cart-clocked plant: send only, the cart's next tick need not be waited for
            self.plant.send(0.0, 0.0) if self._clocked else self.plant.step(0.0, 0.0)  # type: ignore[attr-defined]
            self.state.zero_volts_sent = True
        except Exception as exc:  # a vanished port: still close what can be closed
            self.state.failure = self.state.failure or f"could not send zero volts: {exc}"
        y = self._y
        if self.state.zero_volts_sent and y is not None:
            k = self.state.rows
            time_s = 0.0 if self._last_time_s is None else self._last_time_s + self.period_s
            last = min(k, self.n_ticks - 1)
            ra, rb = (self.ref_a[last], self.ref_b[last]) if self.n_ticks else (0.0, 0.0)
            try:
                ya, yb = y.speed_a_rad_s, y.speed_b_rad_s
                self._log((time_s, 0.0, 0.0, ya, yb, k, ra, rb, ya, yb, 0.0), y, self.now_s())
            except OutputError:
                pass  # kept in state.incomplete by _log
            except Exception as exc:
                self.state.sink_errors.append(f"the stop row: {exc}")
        try:
            self.plant.close()
        except Exception as exc:
            self.state.failure = self.state.failure or f"could not close the plant: {exc}"
        for s in self.sinks:
            try:
                s.close()
            except OutputError as exc:
                self.state.output_failed(exc)
            except Exception as exc:  # report, but close the others too
                self.state.sink_errors.append(f"{type(s).__name__}: {exc}")


def run_in_memory(
    plant: Plant,
    controllers: Mapping[str, Controller],
    references: Mapping[str, PerTick],
    *,
    period_s: float,
    voltage_limit_v: float,
) -> tuple[dict[str, NDArray[np.float64]], LoopState]:
    """Run into a :class:`MemorySink` (with the stop row): the trace columns and what happened (a
    plant fault in ``state.failure``)."""
    clock, memory = SimulatedClock(), MemorySink()
    loop = ControlLoop(plant, controllers, references, [memory], now_s=clock.now_s,
                       voltage_limit_v=voltage_limit_v, period_s=period_s)  # fmt: skip
    executor, loop_tick = BackToBackExecutor(period_s, max_ticks=loop.n_ticks), loop.tick
    try:
        loop.start()
        executor.run(lambda k: loop_tick(k, 0.0, 0.0, k * period_s), loop.idle)
    except PlantError as exc:
        loop.state.failure = str(exc)
    finally:
        loop.finish()
    return memory.arrays(), loop.state


@dataclass(frozen=True)
class ExperimentResult:
    """A recorded experiment: the trace of the ticks done (simulated plants add ``true_speed_a``,
    ``true_speed_b``), whether Ctrl-C stopped it early, and why the plant did."""

    trace: Trace
    interrupted: bool
    failure: str | None = None


def run_experiment(
    plant: Plant,
    voltage_a_v: ArrayLike,
    voltage_b_v: ArrayLike,
    *,
    on_tick: Callable[[int], None] | None = None,
    source: str | None = None,
    sink: Sink | None = None,
) -> ExperimentResult:
    """Apply the voltage sequences (V per tick) and record them with the measured speeds (rows as
    :mod:`cartctl.plants.base` numbers them). The plant is reset first and closed on every path
    (a stop signal meanwhile is only noted: :func:`cartctl.stopping.received`); Ctrl-C, a
    PlantError or an error of cartctl's own after the first tick ends the run with the ticks so
    far. ``on_tick`` gets the number of ticks done. ``sink`` gets each row as it is recorded (opened
    with the trace's columns at the first measurement) and is closed after the plant; a failed
    write (OutputError) stops the experiment and is raised."""
    ua = np.asarray(voltage_a_v, dtype=float)
    ub = np.asarray(voltage_b_v, dtype=float)
    if ua.ndim != 1 or ua.shape != ub.shape:
        raise InputError(
            f"voltage sequences must be 1-D and equally long, got {ua.shape} and {ub.shape}"
        )
    rows: list[list[float]] = []  # row k: tick k's time, voltages and speeds (unknown: NaN)
    names, width = (*REQUIRED_COLUMNS, *TRUE_SPEED_COLUMNS), 0  # the row's, true speeds last
    interrupted, failure = False, None
    idle = getattr(sink, "idle", None) if isinstance(plant, ClockedPlant) else None
    try:
        y = plant.reset()
        for k in range(ua.size):
            with held():  # the row kept and streamed, or neither
                tick = getattr(plant, "tick_index", k)  # a cart's from its first (lost: skipped)
                true = (y.true_speed_a_rad_s, y.true_speed_b_rad_s)
                row = (tick * plant.period_s, ua[k], ub[k], y.speed_a_rad_s, y.speed_b_rad_s, *true)
                rows.append([np.nan if v is None else float(v) for v in row])
                if sink is not None:
                    if not width:  # the first row: the trace's columns (true speeds if it has them)
                        width = 7 if None not in true else 5
                        sink.open(names[:width])
                    sink.write(rows[-1][:width])
            if idle is not None:  # a cart: the block written after the command, as run's loop
                plant.send(float(ua[k]), float(ub[k]))  # type: ignore[attr-defined]
                with held():  # the block written whole: a stop signal waits for it
                    idle()
                y = plant.receive()  # type: ignore[attr-defined]
            else:
                y = plant.step(float(ua[k]), float(ub[k]))
            if on_tick is not None:
                on_tick(k + 1)
    except KeyboardInterrupt:
        interrupted = True
    except OutputError:  # the file cannot hold the experiment: stop it
        raise
    except Exception as exc:  # a plant's fault, or cartctl's own: the ticks so far are kept
        if not rows:  # nothing recorded: the plant never worked; say so as such
            raise
        internal = not isinstance(exc, PlantError)
        failure = f"internal error: {type(exc).__name__}: {exc}" if internal else str(exc)
    finally:
        with deferred():  # zero volts and the port closed whole; the caller sees the signal
            try:
                plant.close()
            finally:
                if sink is not None:
                    sink.close()
    table = np.array(rows, dtype=float).reshape(len(rows), 7)
    keep = 7 if rows and not np.isnan(table[:, 5:]).any() else 5
    columns = {name: table[:, j] for j, name in enumerate(names[:keep])}
    return ExperimentResult(Trace.from_columns(columns, source=source), interrupted, failure)
