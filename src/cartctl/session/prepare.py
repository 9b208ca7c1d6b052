"""Everything a run needs before its first tick, with every refusal, in the order users meet them:
the controller file (its period before its coefficients), the plant, then the tick, the sim
plant's models, the loop delay and the references' reach (the last two shared with ``tune``).
A plant made before a refusal (:class:`~cartctl.errors.InputError`) is closed again.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cartctl.cart import PERIOD_S
from cartctl.choices import DEFAULT_CONNECT_TIMEOUT_S, check_duration, find_file
from cartctl.errors import CartctlError, DataWarning, InputError

if TYPE_CHECKING:
    from cartctl.design.controllerfile import ControllerFile
    from cartctl.link.bridge import EchoDelays
    from cartctl.model import ArxModel
    from cartctl.plants.base import Plant
    from cartctl.reference import ReferenceSchedule

DEFAULT_CONTROLLER = Path("controllers/pi.toml")
"""The default on every plant: the simulators and the bridge (version 2) all have loop delay 1."""
REACH_REFUSE_FACTOR = 2.0
"""A reference beyond this many times what a motor reaches at the voltage limit is refused."""

__all__ = ["DEFAULT_CONTROLLER", "PreparedRun", "check_loop_delay", "check_reach", "prepare_run"]


@dataclass
class PreparedRun:
    """A run ready for its first tick: the plant made (a cart connected), its loop delay (None:
    not known)."""

    controller_file: ControllerFile
    controllers: dict[str, Any]
    plant: Plant
    description: str
    loop_delay_ticks: int | None
    voltage_limit_v: float
    references: dict[str, ReferenceSchedule]
    ticks: int

    @property
    def period_s(self) -> float:
        return float(self.plant.period_s)


def check_reach(
    references: dict[str, ReferenceSchedule],
    models: dict[str, ArxModel],
    limit_v: float,
    where: str,
) -> None:
    """Refuse a reference beyond what a motor reaches (its stable model's DC gain times the
    voltage limit) by :data:`REACH_REFUSE_FACTOR`; warn about one reached only saturated."""
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
    _warn(f"{what}: the voltage saturates and the speed will not settle there")


def _warn(text: str) -> None:
    """A DataWarning located at the line that called the caller (prepare_run's, or its caller's)."""
    warnings.warn(text, DataWarning, stacklevel=3)


def _fitting_controller(controller: ControllerFile, given: str, delay: int) -> str | None:
    """A shipped controller file designed for ``delay``, the same method first (or None)."""
    from cartctl.design.controllerfile import load_controller

    folders = dict.fromkeys([DEFAULT_CONTROLLER.parent, Path(given).parent])
    shipped = ("pi.toml", "poles.toml", "serial-pi.toml", "serial-poles.toml")  # serial-*: 3 ticks
    for name in sorted(  # the same method first
        shipped, key=lambda n: n.removeprefix("serial-").removesuffix(".toml") != controller.method
    ):
        for path in (folder / name for folder in folders):
            found = find_file(path)  # a shipped name: also the package's copy
            if found.is_file() and found.resolve() != find_file(given).resolve():
                with suppress(CartctlError):
                    if load_controller(found).loop_delay_ticks == delay:
                        return str(path)
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
    """Refuse a controller designed for another loop delay than the plant's (with ``allow``: warn);
    an unknown delay (None) is not checked, an unclear ``measured`` one (a probe) only warns."""
    designed = controller.loop_delay_ticks
    if delay is None or designed is None:
        return
    if measured is not None and not measured.clear:
        _warn(
            f"the loop delay of the plant '{plant}' is not clear: {measured.describe()}; "
            f"{given} is designed for {designed}: running it, watching the delay"
        )
        return
    if designed == delay:
        return
    problem = (
        f"{given} is designed for a loop delay of {designed} tick(s) but the plant '{plant}' has "
        f"{delay}" + ("" if measured is None else f" (measured: {measured.describe()})")
    )
    if allow:
        _warn(f"{problem}; running it anyway (--allow-delay-mismatch)")
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


def prepare_run(
    controller: str | Path | ControllerFile,
    *,
    plant: str,
    duration_s: float,
    reference: str,
    reference_b: str | None = None,
    given: str | None = None,
    model: str | Path,
    preset: str = "ground",
    noise_std_rad_s: float = 0.0,
    seed: int | None = None,
    connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    voltage_limit_v: float | None = None,
    force: bool = False,
    allow_unstable: bool = False,
    allow_delay_mismatch: bool = False,
    make_plant: Callable[..., tuple[Plant, str]] | None = None,
    build_controllers: Callable[..., dict[str, Any]] | None = None,
    before_plant: Callable[[], None] | None = None,
) -> PreparedRun:
    """Load, make and check everything a run needs (InputError for whatever it refuses).

    ``given`` names the controller file in messages; the references (b's default a's) span
    ``round(duration_s / Ts)`` ticks; ``model`` is the sim plant's model file. ``make_plant`` and
    ``build_controllers`` replace the factory's and the controller file's; ``before_plant`` runs
    once everything that needs no plant is checked.
    """
    from cartctl.data.modelfile import load_models
    from cartctl.design.controllerfile import ControllerFile, check_period, load_controller
    from cartctl.design.controllerfile import build_controllers as build_from_file
    from cartctl.plants.base import ClockedPlant
    from cartctl.plants.factory import make_plant as factory_make_plant
    from cartctl.reference import ReferenceSchedule, check_step_in_run

    check_duration(duration_s)
    make_plant = make_plant or factory_make_plant
    build_controllers = build_controllers or build_from_file
    given = given if given is not None else str(controller)
    if isinstance(controller, ControllerFile):
        file = controller
    else:  # refused for another tick (the sim plant's models', else the cart's) before its gains
        period_s = load_models(model).period_s if plant == "sim" else PERIOD_S
        file = load_controller(controller, force=force, period_s=period_s)
    if file.ignored:
        more = f" (and {len(file.ignored) - 1} more)" if len(file.ignored) > 1 else ""
        _warn(
            f"--force: {given}: running its gains; ignoring controller_num/controller_den, which "
            f"disagree with them: {file.ignored[0]}{more}"
        )
    limit = file.voltage_limit_v
    if voltage_limit_v is not None:
        if voltage_limit_v > limit:
            raise InputError(
                f"--voltage-limit {voltage_limit_v:g} V is above the {limit:g} V {given} is "
                "designed for; it can only be lowered"
            )
        limit = voltage_limit_v
    if file.model_changed():
        _warn(
            f"{given} was designed on {file.model_path}, which has changed "
            "since (or is gone); redesign with the command in the file's header"
        )
    controllers = build_controllers(file, voltage_limit_v=limit)
    if before_plant is not None:
        before_plant()
    plant_options: dict[str, Any] = {"model_path": model, "preset": preset, "seed": seed}
    plant_options |= {"noise_std_rad_s": noise_std_rad_s, "connect_timeout_s": connect_timeout_s}
    the_plant, description = make_plant(plant, **plant_options)
    try:
        period_s = the_plant.period_s
        check_period(file.path or given, file.period_s, period_s)  # a file given as loaded
        own = getattr(the_plant, "models", None)  # the sim plant's
        checked = own if own is not None and not allow_unstable else ()
        for motor, m in zip("ab", checked, strict=False):
            if not m.is_stable():  # it runs away: refused (--allow-unstable overrides)
                raise InputError(
                    f"{model}: motor {motor}'s model is {m.stability()} (pole at |z| = "
                    f"{m.pole_radius():.4g}): a simulation of it runs away whatever the "
                    "controller does; identify it again, or pass --allow-unstable"
                )
        if isinstance(the_plant, ClockedPlant):
            the_plant.connect()  # a cart: connected before any driving, its delay probed
            measure = getattr(the_plant, "measure_loop_delay", None)  # the echo, at zero volts
            delay = None if measure is None else int(measure())
        else:
            delay = getattr(the_plant, "loop_delay_ticks", None)  # sim and physics know theirs
        measured = getattr(the_plant, "probe_delays", None)
        check_loop_delay(file, given, plant, delay, allow=allow_delay_mismatch, measured=measured)
        n = max(1, round(duration_s / period_s))
        if reference_b and "b" not in controllers:
            raise InputError(f"--reference-b: {given} has no controller for motor b")
        specs = {"a": reference, "b": reference_b or reference}
        references = {  # a motor the file has no controller for is held at 0 V: nothing to follow
            m: ReferenceSchedule(spec if m in controllers else "const:0", n, period_s, m)
            for m, spec in specs.items()
        }
        for option, spec in (("--reference", reference), ("--reference-b", reference_b or "")):
            check_step_in_run(spec, n, period_s, option)  # a step after the run never acts
        if own is not None:
            check_reach(references, dict(zip("ab", own, strict=True)), limit, str(model))
        else:  # the models the controller was designed on, if that file is still readable
            try:
                designed = dict(load_models(file.model_path).motors)
            except (CartctlError, OSError):
                designed = {}
            check_reach(references, designed, limit, file.model_path)
    except BaseException:
        the_plant.close()
        raise
    return PreparedRun(file, controllers, the_plant, description, delay, limit, references, n)
