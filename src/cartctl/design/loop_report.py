"""The robustness analysis of designs: S and T with their peaks, the load-disturbance step, and the
damping and natural frequency of each closed-loop pole, per motor.

Where it sits: in ``cartctl design``, after :func:`cartctl.design.make.design_models`. Each motor's
controller is taken as the loop runs it (:mod:`cartctl.design.controller_ss`), on the loop it was
designed for (the model with the design's extra delay). Its figures are added to the motor's
``design --json`` entry (:meth:`MotorAnalysis.entry`) and drawn by
:mod:`cartctl.design.analysis_plots`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cartctl.design.controller_ss import ControllerStateSpace, controller_state_space
from cartctl.design.damping import pole_table
from cartctl.design.disturbance import (
    DEFAULT_DISTURBANCE_V,
    DisturbanceResponse,
    simulate_disturbance,
)
from cartctl.design.make import Designs
from cartctl.design.sensitivity import LoopShape, loop_shape

__all__ = ["MotorAnalysis", "analyse_designs"]


@dataclass(frozen=True, eq=False)
class MotorAnalysis:
    """One motor's loop analysis.

    Attributes
    ----------
    controller : ControllerStateSpace
        The controller as the loop runs it.
    shape : LoopShape
        L, S and T on a frequency grid with the peaks.
    disturbance : DisturbanceResponse
        The simulated load-disturbance step.
    pole_table : list of dict
        Per closed-loop pole ``{"re", "im", "damping", "freq_hz"}``.
    """

    controller: ControllerStateSpace
    shape: LoopShape
    disturbance: DisturbanceResponse
    pole_table: list[dict[str, Any]]

    def entry(self) -> dict[str, Any]:
        """The keys this analysis adds to (or refines in) a motor's ``design --json`` entry.

        ``sensitivity_peak`` and ``sensitivity_peak_db`` are those of the loop as it runs: the
        same loop as before for the PI on the measurement and for pole placement (refined between
        grid points), the PI with its estimator for ``--estimator kalman``.
        """
        return {
            "sensitivity_peak": self.shape.sensitivity_peak,
            **self.shape.to_dict(),
            "disturbance": self.disturbance.to_dict(),
            "closed_loop_pole_table": self.pole_table,
        }


def analyse_designs(
    designs: Designs, *, disturbance_v: float = DEFAULT_DISTURBANCE_V
) -> dict[str, MotorAnalysis]:
    """The analysis of every motor of ``designs``.

    Parameters
    ----------
    designs : Designs
        From :func:`cartctl.design.make.design_models`.
    disturbance_v : float
        The load-disturbance step at the plant input (V).
    """
    request = designs.request
    extra = request.extra_delay_ticks
    out: dict[str, MotorAnalysis] = {}
    for m, made in designs.motors.items():
        model = designs.models[m]
        ss = controller_state_space(request.method, made.file_entry, model.period_s)
        dist = simulate_disturbance(
            made.controller, model, disturbance_v=disturbance_v, extra_delay_ticks=extra
        )
        table = pole_table(made.entry["closed_loop_poles"], model.period_s)
        out[m] = MotorAnalysis(ss, loop_shape(ss, model, extra), dist, table)
    return out
