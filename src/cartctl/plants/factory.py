"""Build a plant from its command-line name (contract 2: ``sim``, ``physics``, ``virtual``, ``serial:PORT``)."""

from __future__ import annotations

from pathlib import Path

from cartctl.errors import InputError
from cartctl.modelfile import load_models
from cartctl.plants.base import Plant

PLANT_NAMES = ("sim", "physics", "virtual", "serial:PORT")
DEFAULT_MODEL = Path("models/ground.toml")


def make_plant(
    spec: str,
    *,
    model_path: str | Path = DEFAULT_MODEL,
    preset: str = "ground",
    noise_std_rad_s: float = 0.0,
    seed: int | None = None,
) -> tuple[Plant, str]:
    """Create the plant named ``spec``.

    Parameters
    ----------
    spec : str
        'sim' (the ARX models of ``model_path``), 'physics' (the physical simulator with
        ``preset``), 'virtual' or 'serial:PORT'.
    model_path : str or Path
        Model file for 'sim'.
    preset : str
        'air' or 'ground', for 'physics'.
    noise_std_rad_s : float
        Extra white measurement noise (rad/s) for simulated plants; 0 = off.
    seed : int, optional
        Noise seed.

    Returns
    -------
    plant : Plant
    description : str
        One line saying what the plant is, for summaries and provenance.
    """
    if spec == "sim":
        models = load_models(model_path)
        missing = [m for m in ("a", "b") if m not in models.motors]
        if missing:
            raise InputError(
                f"the sim plant needs models of both motors; {model_path} lacks {missing}"
            )
        from cartctl.plants.sim import ArxPlant

        plant = ArxPlant(
            models.motors["a"], models.motors["b"], noise_std_rad_s=noise_std_rad_s, seed=seed
        )
        return plant, f"sim ({model_path})"
    if spec == "physics":
        from cartctl.plants.physics import PhysicsPlant

        return (
            PhysicsPlant(preset, noise_std_rad_s=noise_std_rad_s, seed=seed),
            f"physics (preset {preset})",
        )
    if spec == "virtual" or spec.startswith("serial:"):
        raise InputError(f"plant '{spec}' is not built yet; use 'sim' or 'physics'")
    raise InputError(f"unknown plant '{spec}'; expected one of {', '.join(PLANT_NAMES)}")
