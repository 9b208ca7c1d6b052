"""Open-loop experiments: drive a plant with voltage sequences and record a trace.

``cartctl excite`` runs here. The plant paces the run: a simulated plant runs as fast as the CPU
allows, a serial cart at its own 10 ms tick. Whatever happens (an error, Ctrl-C), the plant is left
at zero volts and the samples recorded so far are returned.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from cartctl.data.trace import Trace
from cartctl.errors import InputError, PlantError
from cartctl.plants.base import Plant


@dataclass(frozen=True)
class ExperimentResult:
    """A recorded experiment.

    Attributes
    ----------
    trace : Trace
        The trace columns; simulated plants add ``true_speed_a`` and ``true_speed_b``.
    interrupted : bool
        True when Ctrl-C stopped the run early (the trace holds the ticks done so far).
    failure : str or None
        Why the plant stopped the run early (a serial cart gone silent, a vanished port); the
        trace holds the ticks done so far.
    """

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
) -> ExperimentResult:
    """Apply the voltage sequences tick by tick and record commanded voltages and measured speeds.

    Ctrl-C or a plant fault (:class:`~cartctl.errors.PlantError`) after the first tick ends the run
    early with the ticks recorded so far; a fault before it propagates.

    Row k of the trace holds the voltage commanded at tick k and the speed measured at tick k
    (the trace columns), so the report's model applies to the trace as written.

    Parameters
    ----------
    plant : Plant
        The plant; it is reset first and closed (zero volts) at the end, on every path.
    voltage_a_v, voltage_b_v : array_like, shape (n,)
        Commanded voltage per tick (V).
    on_tick : callable, optional
        Called with the number of ticks done (for a progress bar).
    source : str, optional
        Recorded as the trace's source.

    Returns
    -------
    ExperimentResult
    """
    ua = np.asarray(voltage_a_v, dtype=float)
    ub = np.asarray(voltage_b_v, dtype=float)
    if ua.ndim != 1 or ua.shape != ub.shape:
        raise InputError(
            f"voltage sequences must be 1-D and equally long, got {ua.shape} and {ub.shape}"
        )
    n = ua.size
    speed = np.zeros((n, 2))
    true_speed = np.full((n, 2), np.nan)
    done = 0
    interrupted = False
    failure = None
    try:
        y = plant.reset()
        for k in range(n):
            speed[k] = y.speed_a_rad_s, y.speed_b_rad_s
            if y.true_speed_a_rad_s is not None and y.true_speed_b_rad_s is not None:
                true_speed[k] = y.true_speed_a_rad_s, y.true_speed_b_rad_s
            done = k + 1
            y = plant.step(float(ua[k]), float(ub[k]))
            if on_tick is not None:
                on_tick(done)
    except KeyboardInterrupt:
        interrupted = True
    except PlantError as exc:
        if done == 0:  # nothing recorded: the plant never worked; say so as such
            raise
        failure = str(exc)
    finally:
        plant.close()
    columns = {
        "time_s": np.arange(done) * plant.period_s,
        "voltage_a": ua[:done],
        "voltage_b": ub[:done],
        "speed_a": speed[:done, 0],
        "speed_b": speed[:done, 1],
    }
    if done and not np.isnan(true_speed[:done]).any():
        columns["true_speed_a"] = true_speed[:done, 0]
        columns["true_speed_b"] = true_speed[:done, 1]
    return ExperimentResult(Trace.from_columns(columns, source=source), interrupted, failure)
