"""What a run refuses (or flags) before it drives: a controller for another loop delay, a
reference no motor can follow."""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from cartctl.errors import CartctlError, DataWarning, InputError

if TYPE_CHECKING:  # imported where used: the parser takes this module's defaults (light)
    from cartctl.design.controllerfile import ControllerFile
    from cartctl.link.loop_delay import EchoDelays
    from cartctl.model import ArxModel
    from cartctl.reference import ReferenceSchedule

DEFAULT_CONTROLLER = Path("controllers/pi.toml")
"""The default on every plant: the simulators and the bridge (version 2) all have loop delay 1."""
SHIPPED_CONTROLLERS = ("pi.toml", "poles.toml", "serial-pi.toml", "serial-poles.toml")
"""Offered when a file does not fit a plant; ``serial-*`` for a serial loop of 3 ticks."""
REACH_REFUSE_FACTOR = 2.0
"""A reference beyond this many times what a motor reaches at the voltage limit is refused."""

__all__ = ["DEFAULT_CONTROLLER", "check_loop_delay", "check_reach"]


def check_reach(
    references: dict[str, ReferenceSchedule],
    models: dict[str, ArxModel],
    limit_v: float,
    where: str,
) -> None:
    """Refuse a reference no motor can follow, warn (one line) about one reached only saturated:
    what a motor reaches is its (stable) model's DC gain times the voltage limit."""
    beyond: list[str] = []
    refuse = False
    for motor, ref in references.items():
        model = models.get(motor)
        if model is None or not model.is_stable() or not len(ref):
            continue
        reach = abs(model.dc_gain()) * limit_v
        peak = ref.peak_abs()
        if math.isfinite(reach) and peak > reach:
            beyond.append(f"motor {motor} {peak:.4g} rad/s (it reaches about {reach:.3g})")
            refuse = refuse or peak > REACH_REFUSE_FACTOR * reach
    if not beyond:
        return
    what = (
        f"the reference asks for {', '.join(beyond)} at {limit_v:g} V, by the DC gains in {where}"
    )
    if refuse:
        raise InputError(f"{what}; give a reference within that")
    warnings.warn(f"{what}: the voltage saturates and the speed will not settle there",
                  DataWarning, stacklevel=2)  # fmt: skip


def _fitting_controller(controller: ControllerFile, given: str, delay: int) -> str | None:
    """A shipped controller file designed for ``delay``, the same method first (or None)."""
    from cartctl.design.controllerfile import load_controller

    folders = dict.fromkeys([DEFAULT_CONTROLLER.parent, Path(given).parent])

    def other_method(name: str) -> bool:
        return name.removeprefix("serial-").removesuffix(".toml") != controller.method

    for name in sorted(SHIPPED_CONTROLLERS, key=other_method):
        for folder in folders:
            path = folder / name
            if not path.is_file() or path.resolve() == Path(given).resolve():
                continue
            try:
                if load_controller(path).loop_delay_ticks == delay:
                    return str(path)
            except CartctlError:
                continue
    return None


def check_loop_delay(
    controller: ControllerFile,
    given: str,
    plant: str,
    delay: int | None,
    *,
    allow: bool,
    measured: EchoDelays | None = None,
) -> None:
    """Refuse (InputError) a controller designed for another loop delay than the plant's.

    With ``allow`` a warning; an unknown plant delay (None) is not checked; a ``measured`` delay
    (a serial plant's probe) that is not clear is never refused: the run warns and goes on.
    """
    designed = controller.loop_delay_ticks
    if delay is None or designed is None:
        return
    if measured is not None and not measured.clear:
        warnings.warn(
            f"the loop delay of the plant '{plant}' is not clear: {measured.describe()}; "
            f"{given} is designed for {designed}: running it, watching the delay",
            DataWarning,
            stacklevel=2,
        )
        return
    if designed == delay:
        return
    problem = (
        f"{given} is designed for a loop delay of {designed} tick(s) but the plant '{plant}' has "
        f"{delay}" + ("" if measured is None else f" (measured: {measured.describe()})")
    )
    if allow:
        warnings.warn(f"{problem}; running it anyway (--allow-delay-mismatch)", DataWarning,
                      stacklevel=2)  # fmt: skip
        return
    fit = _fitting_controller(controller, given, delay)
    if fit is not None:
        hint = f"use {fit} (designed for {delay})"
    else:
        extra = int(controller.request.get("extra_delay_ticks", 0)) + delay - designed
        hint = (
            f"redesign it with --extra-delay {extra}"
            if extra >= 0
            else "redesign it on a model of this loop"
        )
    raise InputError(f"{problem}; {hint} or pass --allow-delay-mismatch")
