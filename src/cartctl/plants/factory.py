"""Build a plant from its ``--plant`` name ( ``sim``, ``physics``, ``virtual``, ``serial:PORT``)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from cartctl.choices import DEFAULT_CONNECT_TIMEOUT_S, DEFAULT_MODEL, check_finite
from cartctl.data.modelfile import load_models
from cartctl.errors import InputError
from cartctl.plants.base import Plant

SIMULATED = ("sim", "physics")
"""Plant kinds that run in this process on a simulated clock (``--fast``)."""


PLANTS_USING = {
    "--model": ("sim",),
    "--preset": ("physics", "virtual"),
    "--noise": ("sim", "physics", "virtual"),
    "--seed": ("sim", "physics", "virtual"),
    "--connect-timeout": ("virtual", "serial"),
}
"""The plant kinds that use each plant option of the command line (:func:`make_plant`'s)."""

MAX_NOISE_RAD_S = 1e3
"""The largest ``--noise`` (rad/s): the cart turns at some 30 rad/s; beyond, a trace is noise."""


def plant_kind(spec: str) -> str:
    """The kind of a ``--plant`` name: 'sim', 'physics', 'virtual', 'serial', or the name as given."""
    kind = spec.partition(":")[0]
    return kind if kind in ("physics", "virtual", "serial") else spec


def check_option_used(option: str, spec: str, named: str = "--plant") -> None:
    """InputError if the plant ``spec`` (given as ``named``) does not use ``option``."""
    *others, last = PLANTS_USING[option]
    if plant_kind(spec) not in (*others, last):
        uses = f"{', '.join(others)} and {last} plants" if others else f"{last} plant"
        raise InputError(f"{option} is for the {uses}; {named} {spec} does not use it")


def check_plant_options(
    spec: str,
    *,
    noise_std_rad_s: float = 0.0,
    connect_timeout_s: float = 1.0,
    given: Iterable[str] = (),
    named: str = "--plant",
) -> None:
    """The plant options' refusals, in the command line's words, before a plant is made: the
    noise (rad/s) and the connect timeout (s) in range, and no option in ``given`` (its name on
    the command line) that the plant ``spec`` (given as ``named``) does not use: ``--seed``
    without noise on a simulated plant (it seeds nothing else there)."""
    noise = check_finite(noise_std_rad_s, "--noise")
    if not 0.0 <= noise <= MAX_NOISE_RAD_S:
        raise InputError(
            f"--noise must be a standard deviation >= 0 rad/s and up to {MAX_NOISE_RAD_S:g}, "
            f"got {noise:g}"
        )
    timeout = check_finite(connect_timeout_s, "--connect-timeout")
    if timeout <= 0.0:
        raise InputError(f"--connect-timeout must be a positive number of seconds, got {timeout:g}")
    for option in sorted(given):  # after the ranges: those say more
        check_option_used(option, spec, named)
    if "--seed" in given and noise == 0.0 and plant_kind(spec) in SIMULATED:
        raise InputError(
            f"--seed seeds the measurement noise, which is off; {named} {spec} uses it for "
            "nothing else: give --noise RAD_S too, or no --seed"
        )


def physics_options(text: str) -> dict[str, Any]:
    """The PhysicsPlant keyword arguments ``physics:KEY=VALUE,...`` sets: ``actuation_ms`` and
    ``reversed_motors`` (from ``reverse_a=1`` / ``reverse_b=1``)."""
    from cartctl.plants.physics_params import check_actuation_ms

    options: dict[str, Any] = {}
    seen: set[str] = set()
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, value = (part.strip() for part in item.partition("="))
        if sep and key in seen:
            raise InputError(f"physics option {key} is given twice; give it once")
        seen.add(key)
        if sep and key in ("reverse_a", "reverse_b"):
            if value not in ("0", "1"):
                raise InputError(f"physics option {key} must be 0 or 1, got '{value}'")
            motors = str(options.get("reversed_motors", "")).replace(key[-1], "")
            options["reversed_motors"] = motors + (key[-1] if value == "1" else "")
            continue
        if not sep or key != "actuation_ms":
            raise InputError(
                f"bad physics option '{item}'; expected actuation_ms=X (ms in (0, 10]), "
                "reverse_a=1 or reverse_b=1"
            )
        options["actuation_ms"] = check_actuation_ms(value)
    return options


def check_plant_name(spec: str) -> str:
    """The kind of plant ``spec`` names, its options checked, without making it (InputError)."""
    kind, _, options = spec.partition(":")
    if spec == "sim":
        return kind
    if kind == "physics":
        physics_options(options)
        return kind
    if kind == "virtual":
        from cartctl.link.cart_faults import CartFaults

        CartFaults.parse(options)
        return kind
    if kind == "serial" and spec.startswith("serial:"):
        if not options:
            raise InputError("plant 'serial:' needs a port, e.g. serial:/dev/ttyACM0")
        return kind
    names = "sim, physics, physics:actuation_ms=X, virtual, virtual:OPTIONS, serial:PORT"
    raise InputError(f"unknown plant '{spec}'; expected one of {names}")


def make_plant(
    spec: str,
    *,
    model_path: str | Path = DEFAULT_MODEL,
    preset: str = "ground",
    noise_std_rad_s: float = 0.0,
    seed: int | None = None,
    connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    motors: str = "ab",
) -> tuple[Plant, str]:
    """The plant named ``spec`` (docs/plants.md) and one line saying what it is.

    ``model_path``: the ``sim`` plant's models; ``preset``: ``air`` or ``ground`` (physics);
    ``noise_std_rad_s``: extra white measurement noise of a simulated plant (0: off);
    ``connect_timeout_s``: a serial cart's longest wait for its first HEARTBEAT (s); ``motors``:
    those driven (a ``sim`` model file may lack the others, which stay at rest). A serial
    plant is returned unconnected (``connect()`` opens the port)."""
    kind = check_plant_name(spec)
    options = spec.partition(":")[2]
    noise: dict[str, Any] = {"noise_std_rad_s": noise_std_rad_s, "seed": seed}
    if kind == "sim":
        models = load_models(model_path)
        missing = [m for m in motors if m not in models.motors]
        if missing:
            what = "models of both motors" if len(motors) == 2 else f"a model of motor {motors}"
            raise InputError(f"the sim plant needs {what}; {model_path} lacks {missing}")
        from cartctl.plants.sim import ArxPlant

        have, delay = models.motors, models.loop_delay_ticks
        a, b = (have.get(m) or next(iter(have.values())) for m in "ab")  # idle: 0 V stays 0 rad/s
        plant: Plant = ArxPlant(a, b, loop_delay_ticks=delay, **noise)
        return plant, f"sim ({model_path})"
    if kind == "physics":
        from cartctl.plants.physics import PhysicsPlant

        physics = physics_options(options)
        plant = PhysicsPlant(preset, **noise, **physics)
        timing = ""
        if "actuation_ms" in physics:
            timing = f", command lands {physics['actuation_ms']:g} ms after its tick"
        if physics.get("reversed_motors"):
            timing += f", motor(s) {physics['reversed_motors']} wired backwards"
        return plant, f"physics (preset {preset}{timing})"
    if kind == "virtual":
        from cartctl.link.virtual_cart import CartFaults, VirtualCart, VirtualSerialCart

        faults = CartFaults.parse(options)
        cart = VirtualCart(preset, faults=faults, **noise)
        shown = f", faults {options}" if faults != CartFaults() else ""
        return VirtualSerialCart(
            cart, connect_timeout_s=connect_timeout_s
        ), f"virtual cart on {cart.port} (physics preset {preset}{shown})"
    from cartctl.link.serial_cart import SerialCart

    return SerialCart(options, connect_timeout_s=connect_timeout_s), f"cart on {options}"
