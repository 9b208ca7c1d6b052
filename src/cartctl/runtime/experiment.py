"""Open-loop experiments (``cartctl excite``): drive a plant with voltage sequences, record a trace.

The plant paces the run (a simulated one as fast as the CPU allows, a cart at its 10 ms tick)."""

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
    """A recorded experiment: the trace (simulated plants add ``true_speed_a``, ``true_speed_b``),
    whether Ctrl-C stopped it early, and why the plant did (a cart gone silent, a vanished port);
    either way the trace holds the ticks done."""

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
    """Apply the voltage sequences (V per tick) and record them with the measured speeds.

    Row k holds the voltage commanded at tick k and the speed measured at tick k, so the report's
    model applies to the trace as written. The plant is reset first and closed (zero volts) on
    every path; Ctrl-C or a :class:`~cartctl.errors.PlantError` after the first tick ends the run
    with the ticks recorded so far (a fault before it propagates). ``on_tick`` gets the number of
    ticks done (a progress bar); ``source`` is recorded as the trace's.
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
