"""Everything a run needs before its first tick, with every refusal, in the order users meet them.

The controller file first (its period before its coefficients), then the plant, then what
depends on both: the tick, the sim plant's models, the loop delay (measured on a cart), and the
references against what the motors reach. A refusal is an :class:`~cartctl.errors.InputError`
whose line names the option or file; a plant made before a refusal is closed again.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cartctl.choices import DEFAULT_CONNECT_TIMEOUT_S
from cartctl.errors import DataWarning, InputError
from cartctl.session.checks import (
    check_loop_delay,
    check_reach,
    models_designed_on,
    refuse_unstable,
)

if TYPE_CHECKING:
    from cartctl.design.controllerfile import ControllerFile
    from cartctl.plants.base import Plant
    from cartctl.reference import ReferenceSchedule

__all__ = ["PreparedRun", "prepare_run"]


@dataclass
class PreparedRun:
    """A run ready for its first tick: the plant is made (a cart connected) and nothing refused."""

    controller_file: ControllerFile
    controllers: dict[str, Any]
    """The run-time controller of each motor (``a``, ``b``)."""
    plant: Plant
    description: str
    """The plant in words, for the summary."""
    loop_delay_ticks: int | None
    """The plant's loop delay (measured on a cart; None where the plant does not know it)."""
    voltage_limit_v: float
    references: dict[str, ReferenceSchedule]
    ticks: int

    @property
    def period_s(self) -> float:
        return float(self.plant.period_s)


def _measured_delay(plant: Plant) -> int | None:
    """A serial plant's loop delay from the echo (drive = 0, zero volts), before any driving."""
    measure = getattr(plant, "measure_loop_delay", None)
    return None if measure is None else int(measure())


def load_run_controller(
    controller: str | Path | ControllerFile,
    *,
    given: str,
    plant: str,
    model: str | Path,
    force: bool = False,
    voltage_limit_v: float | None = None,
) -> tuple[ControllerFile, float]:
    """The controller file for ``plant`` and the voltage limit to run it at.

    Refuses a file for another tick (before its coefficients are looked at) and a
    ``voltage_limit_v`` above the file's; warns when ``--force`` ignores coefficients and when
    the model the file was designed on has changed.
    """
    from cartctl.design.controllerfile import ControllerFile, load_controller
    from cartctl.plants.factory import plant_period_s

    if isinstance(controller, ControllerFile):
        file = controller
    else:
        file = load_controller(controller, force=force, period_s=plant_period_s(plant, model))
    if file.ignored:
        more = f" (and {len(file.ignored) - 1} more)" if len(file.ignored) > 1 else ""
        warnings.warn(
            f"--force: {given}: running its gains; ignoring controller_num/controller_den, which "
            f"disagree with them: {file.ignored[0]}{more}",
            DataWarning,
            stacklevel=2,
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
        warnings.warn(
            f"{given} was designed on {file.model_path}, which has changed "
            "since (or is gone); redesign with the command in the file's header",
            DataWarning,
            stacklevel=2,
        )
    return file, limit


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
    """Load, make and check everything a run needs; the plant is made last but one.

    Parameters
    ----------
    controller : str, Path or ControllerFile
        The controller file (``given`` names it in messages: the path the user gave).
    plant : str
        A plant name (``sim``, ``physics[:…]``, ``virtual[:…]``, ``serial:PORT``).
    duration_s : float
        The run's length; the references are built for ``round(duration_s / Ts)`` ticks.
    reference, reference_b : str
        Reference specs of motor a, and of b (default: a's).
    model : str or Path
        The sim plant's model file (and where an unstable one is named).
    connect_timeout_s : float
        A serial or virtual cart's longest wait for its first HEARTBEAT (s).
    make_plant, build_controllers : callable, optional
        :func:`cartctl.plants.factory.make_plant` and
        :func:`cartctl.design.build.build_controllers` unless given (a test's stand-ins).
    before_plant : callable, optional
        Called once everything that needs no plant is checked, before the plant is made (the
        command warms up the Rerun SDK there, so its first-use cost comes before a cart ticks).

    Raises
    ------
    InputError
        Whatever the run refuses (see :mod:`cartctl.session.checks`).
    """
    from cartctl.plants.base import ClockedPlant
    from cartctl.reference import ReferenceSchedule

    if make_plant is None:
        from cartctl.plants.factory import make_plant as factory_make_plant

        make_plant = factory_make_plant
    if build_controllers is None:
        from cartctl.design.build import build_controllers as build_from_file

        build_controllers = build_from_file
    given = given if given is not None else str(controller)
    file, limit = load_run_controller(controller, given=given, plant=plant, model=model,
                                      force=force, voltage_limit_v=voltage_limit_v)  # fmt: skip
    controllers = build_controllers(file, voltage_limit_v=limit)
    if before_plant is not None:
        before_plant()
    the_plant, description = make_plant(plant, model_path=model, preset=preset,
                                        noise_std_rad_s=noise_std_rad_s, seed=seed,
                                        connect_timeout_s=connect_timeout_s)  # fmt: skip
    try:
        period_s = the_plant.period_s
        if abs(period_s - file.period_s) > 1e-9:
            raise InputError(
                f"the controller is for Ts = {file.period_s} s but the plant ticks at {period_s} s"
            )
        models = getattr(the_plant, "models", None)  # the sim plant's own
        if models is not None and not allow_unstable:
            refuse_unstable(dict(zip("ab", models, strict=True)), str(model))
        if isinstance(the_plant, ClockedPlant):
            the_plant.connect()  # a cart: connected (its delay probed) before any driving
            delay = _measured_delay(the_plant)
        else:
            delay = getattr(the_plant, "loop_delay_ticks", None)  # sim and physics know theirs
        check_loop_delay(file, given, plant, delay, allow=allow_delay_mismatch,
                         measured=getattr(the_plant, "probe_delays", None))  # fmt: skip
        n = max(1, round(duration_s / period_s))
        references = {
            "a": ReferenceSchedule(reference, n, period_s, "a"),
            "b": ReferenceSchedule(reference_b or reference, n, period_s, "b"),
        }
        reach_models = (
            dict(zip("ab", models, strict=True)) if models is not None else models_designed_on(file)
        )
        check_reach(references, reach_models, limit, str(model) if models is not None
                    else file.model_path)  # fmt: skip
    except BaseException:
        the_plant.close()
        raise
    return PreparedRun(file, controllers, the_plant, description, delay, limit, references, n)
