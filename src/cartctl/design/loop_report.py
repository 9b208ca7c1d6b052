"""The robustness analysis of designs: S and T with their peaks, the load-disturbance step, and the
damping and natural frequency of each closed-loop pole, per motor.

Where it sits: in ``cartctl design``, after :func:`cartctl.design.make.design_models`. Each motor's
controller is taken as the loop runs it (:mod:`cartctl.design.controller_ss`), on the loop it was
designed for (the model with the design's extra delay). Its figures are added to the motor's
``design --json`` entry (:meth:`MotorAnalysis.entry`) and drawn by
:mod:`cartctl.design.analysis_plots`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from cartctl.design.controller_ss import ControllerStateSpace, controller_state_space
from cartctl.design.disturbance import (
    DEFAULT_DISTURBANCE_V,
    DisturbanceResponse,
    simulate_disturbance,
)
from cartctl.design.make import Designs
from cartctl.design.sensitivity import LoopShape, loop_shape
from cartctl.model import pole_damping

__all__ = ["LIGHT_DAMPING", "MotorAnalysis", "analyse_designs", "damping_warning", "pole_table"]

LIGHT_DAMPING = 0.1
"""A closed-loop pole with a damping ratio ζ below this rings for many periods: a warning."""


def pole_table(poles: Iterable[list[float]], period_s: float) -> list[dict[str, Any]]:
    """Per pole ``{"re", "im", "damping", "freq_hz"}`` (:func:`cartctl.model.pole_damping`).

    Parameters
    ----------
    poles : iterable of [re, im]
        Discrete poles, as ``closed_loop_poles`` lists them.
    period_s : float
        Sample period Ts (s).
    """
    rows = []
    for re, im in poles:
        damping, freq_hz = pole_damping(complex(re, im), period_s)
        rows.append({"re": re, "im": im, "damping": damping, "freq_hz": freq_hz})
    return rows


def damping_warning(pole_table: list[dict[str, Any]], motor: str) -> str | None:
    """One line naming the least damped closed-loop pole when its ζ is below ``LIGHT_DAMPING``.

    Parameters
    ----------
    pole_table : list of dict
        ``{"re", "im", "damping", "freq_hz"}`` per pole (:func:`pole_table`).
    motor : str
        The motor, named in the line.

    Returns
    -------
    str or None
        None when every ζ is at least ``LIGHT_DAMPING`` (or undefined, at z = 0 and z = 1).
    """
    light = [r for r in pole_table if r["damping"] is not None and r["damping"] < LIGHT_DAMPING]
    if not light:
        return None
    worst = min(light, key=lambda r: r["damping"])
    z = f"{worst['re']:.4f}" + ("" if worst["im"] == 0.0 else f" ± {abs(worst['im']):.4f}j")
    freq = "" if worst["freq_hz"] is None else f" at {worst['freq_hz']:.2f} Hz"
    others = len({(r["re"], abs(r["im"])) for r in light}) - 1
    more = f" ({others} more pole(s) below {LIGHT_DAMPING:g})" if others else ""
    return (
        f"motor {motor}: closed-loop pole z = {z} has damping ζ = {worst['damping']:.3f} < "
        f"{LIGHT_DAMPING:g}{more}: the loop rings{freq} for many periods"
    )


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
    motor : str
        The motor ('a' or 'b'), for the warnings.
    """

    controller: ControllerStateSpace
    shape: LoopShape
    disturbance: DisturbanceResponse
    pole_table: list[dict[str, Any]]
    motor: str = "a"

    def entry(self) -> dict[str, Any]:
        """The keys this analysis adds to (or replaces in) a motor's ``design --json`` entry.

        ``sensitivity_peak`` and ``sensitivity_peak_db`` are those of the loop as it runs: the
        design's own loop for the PI on the measurement and for pole placement (the same numbers),
        the PI with its estimator for ``--estimator kalman``.
        """
        return {
            "sensitivity_peak": self.shape.sensitivity_peak,
            **self.shape.to_dict(),
            "disturbance": self.disturbance.to_dict(),
            "closed_loop_pole_table": self.pole_table,
            "warnings": self.warnings,
        }

    @property
    def warnings(self) -> list[str]:
        """Warnings about this loop (a closed-loop pole with ζ < ``LIGHT_DAMPING``), one line each."""
        line = damping_warning(self.pole_table, self.motor)
        return [] if line is None else [line]


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
        out[m] = MotorAnalysis(ss, loop_shape(ss, model, extra), dist, table, m)
    return out
