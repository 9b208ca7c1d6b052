"""What ``cartctl tune`` refuses before any work: :func:`check_options` bounds what sizes the work
(no numpy, no model), :func:`check_inputs` what ``design`` or ``run`` would refuse for every
setting alike, in their words (a setting only its own design refuses stays a row)."""

from __future__ import annotations

import argparse
import math
from typing import Any

from cartctl.cart import PERIOD_S
from cartctl.cli.commands.options import check_duration, check_jobs
from cartctl.design.request import OPTIONS, check_field  # light: no numpy
from cartctl.errors import InputError

DEFAULT_PLANTS = 200  # sampled plants of --robust
MAX_PLANTS = 10_000
DEFAULT_ACTUATION_MS = (3.0, 10.0)  # the presets' calibrated timing; the next tick's io()
MAX_ACTUATION_TIMINGS = 20
# (plants + 1) × ticks per motor: four float64 arrays of that size per motor in each worker
MAX_PLANT_TICKS = 2_000_000
MAX_TUNE_DURATION_S = 60.0  # a step response settles within a second on this cart
# settings × ticks × runs of a setting: at about 60 µs a tick, some two minutes of one core
MAX_GRID_TICKS = 2_000_000
# settings × (plants + 1) × ticks: at about 0.07 µs a plant-tick, some 15 s of one core
MAX_ROBUST_PLANT_TICKS = 200_000_000


def _ticks(args: argparse.Namespace) -> int:
    return max(1, round(args.duration / PERIOD_S))


def actuation_timings(text: str | None) -> tuple[float, ...]:
    """``--actuation-ms``: the timings (ms) in the order given, () for 'none', the default for
    None; each 0 < X <= 10 to 0.1 ms, no repeats."""
    from cartctl.plants.physics_params import check_actuation_ms

    if text is None:
        return DEFAULT_ACTUATION_MS
    if text.strip() == "none":
        return ()
    items = text.split(",")
    if len(items) > MAX_ACTUATION_TIMINGS:
        raise InputError(f"--actuation-ms takes at most {MAX_ACTUATION_TIMINGS} timings, got "
                         f"{len(items)}")  # fmt: skip
    timings: list[float] = []
    for item in items:
        try:
            ms = check_actuation_ms(item.strip())
        except InputError as exc:
            raise InputError(f"--actuation-ms: {exc}") from None
        if ms in timings:
            raise InputError(f"--actuation-ms lists {ms:g} ms twice")
        timings.append(ms)
    return tuple(timings)


def design_fixed(args: argparse.Namespace) -> dict[str, float]:
    """``--process-noise-v`` and ``--bias-drift-v``, the design fields every setting shares,
    checked as ``cartctl design`` checks them."""
    given = (("process_noise_std_v", args.process_noise_v), ("bias_drift_std_v", args.bias_drift_v))
    fixed = {field: float(check_field(field, value)) for field, value in given if value is not None}
    if fixed and args.method == "pi":  # tune's PI runs on the measurement
        verb = "applies" if len(fixed) == 1 else "apply"
        raise InputError(f"{' and '.join(OPTIONS[f] for f in fixed)} only {verb} to --method poles")
    return fixed


def choice_limits(args: argparse.Namespace) -> Any:
    """``--max-overshoot`` and ``--max-settling`` as :class:`~cartctl.tune.choice.Limits`."""
    from cartctl.tune.choice import Limits

    for option, value in (("--max-overshoot", args.max_overshoot),
                          ("--max-settling", args.max_settling)):  # fmt: skip
        if value is None:
            continue
        if args.choose != "best":
            raise InputError(f"{option} only applies to --choose best")
        if not (math.isfinite(value) and value > 0.0):
            raise InputError(f"{option} must be a number > 0, got {value}")
    return Limits(args.max_overshoot, args.max_settling)


def check_options(args: argparse.Namespace) -> None:
    """The options that size the work, before the grid is built or numpy imported (one line);
    sets ``args.timings`` (``--actuation-ms``) and, with ``--robust``, the defaults of
    ``--plants`` and ``--seed``."""
    check_duration(args.duration)
    if args.duration > MAX_TUNE_DURATION_S:
        raise InputError(f"--duration of a tuning run must be at most {MAX_TUNE_DURATION_S:g} s "
                         f"(each setting is scored on a step response), got {args.duration:g}")  # fmt: skip
    check_field("extra_delay_ticks", args.extra_delay)
    check_jobs(args.jobs)
    if not args.robust:
        given = [o for o, v in (("--plants", args.plants), ("--seed", args.seed),
                                ("--actuation-ms", args.actuation_ms)) if v is not None]  # fmt: skip
        if given:
            raise InputError(f"{' and '.join(given)} only apply to --robust")
    else:
        if args.plant != "sim":
            raise InputError("--robust scores on the model (sim) and the physics --preset (at "
                             "each --actuation-ms); leave out --plant physics")  # fmt: skip
        plants = args.plants = DEFAULT_PLANTS if args.plants is None else args.plants
        args.seed = 1 if args.seed is None else args.seed
        ticks = _ticks(args)
        if not 1 <= plants <= MAX_PLANTS:
            raise InputError(
                f"--plants must be a number of plants in 1..{MAX_PLANTS}, got {plants}"
            )
        if (plants + 1) * ticks > MAX_PLANT_TICKS:
            raise InputError(
                f"--robust with {plants} plants and --duration {args.duration:g} s simulates "
                f"{(plants + 1) * ticks} plant-ticks per motor, more than {MAX_PLANT_TICKS}; use "
                "fewer --plants or a shorter --duration"
            )
    args.timings = actuation_timings(args.actuation_ms) if args.robust else ()
    if (args.choose is None) != (args.out is None):
        raise InputError("--choose N and --out CONTROLLER.toml go together; give both or neither")
    design_fixed(args)


def check_work(args: argparse.Namespace, n_settings: int) -> None:
    """The grid's size against :data:`MAX_GRID_TICKS` and, with ``--robust``,
    :data:`MAX_ROBUST_PLANT_TICKS` (one line naming the options to change)."""
    ticks = _ticks(args)
    runs = 2 + len(args.timings) if args.robust else 1
    if n_settings * ticks * runs > MAX_GRID_TICKS:
        what = f"{n_settings} settings" + (f" ({runs} runs each)" if runs > 1 else "")
        raise InputError(
            f"--grid with {what} and --duration {args.duration:g} s simulates "
            f"{n_settings * ticks * runs} ticks, more than {MAX_GRID_TICKS}; use a coarser --grid "
            "or a shorter --duration"
        )
    work = n_settings * (args.plants + 1) * ticks if args.robust else 0
    if work > MAX_ROBUST_PLANT_TICKS:
        raise InputError(
            f"--robust with {n_settings} settings, {args.plants} plants and --duration "
            f"{args.duration:g} s simulates {work} plant-ticks, more than "
            f"{MAX_ROBUST_PLANT_TICKS}; use a coarser --grid, fewer --plants or a shorter "
            "--duration"
        )


def _choice(text: str | None, n_settings: int) -> int | str | None:
    """``--choose``: None, 'best', or a setting number in 1..n_settings."""
    if text is None or text.strip() == "best":
        return None if text is None else "best"
    try:
        number = int(text)
    except ValueError:
        raise InputError(f"--choose takes a setting number or 'best', got '{text}'") from None
    if not 1 <= number <= n_settings:
        raise InputError(f"--choose must be a setting number in 1..{n_settings}, got {number}")
    return number


def check_inputs(args: argparse.Namespace, n_settings: int) -> None:
    """The model, the plant and the reference, refused as ``design`` and ``run`` refuse them
    (a reference beyond the motors' reach at 12 V included); sets ``args.choose``."""
    from cartctl.cart import SUPPLY_V
    from cartctl.data.modelfile import load_models
    from cartctl.design.make import check_models
    from cartctl.plants.factory import SIMULATED, check_plant_name, plant_kind
    from cartctl.reference import ReferenceSchedule, check_step_in_run
    from cartctl.session.prepare import check_reach

    args.choose = _choice(args.choose, n_settings)
    choice_limits(args)
    if plant_kind(args.plant) not in SIMULATED:
        raise InputError(f"--plant must be sim, physics or physics:actuation_ms=X, got "
                         f"'{args.plant}'")  # fmt: skip
    check_plant_name(args.plant)  # physics:OPTIONS
    models = load_models(args.model)
    check_models(models, ("a", "b"), str(args.model))  # design's line: no setting could run
    period_s = models.period_s if args.plant == "sim" else PERIOD_S  # physics: the cart's tick
    if abs(period_s - models.period_s) > 1e-9:
        raise InputError(
            f"the model is for Ts = {models.period_s} s but the plant ticks at {period_s} s"
        )
    # a bad spec fails here, and one no motor can follow is refused as run refuses it (every
    # setting would saturate)
    n = max(1, round(args.duration / period_s))
    references = {m: ReferenceSchedule(args.reference, n, period_s, m) for m in ("a", "b")}
    check_reach(references, dict(models.motors), SUPPLY_V, str(args.model))
    check_step_in_run(args.reference, n, period_s, "--reference")  # else every setting: no step
