"""Plants: the simulated ARX cart, the physical cart simulator, and (later) the serial cart."""

from cartctl.plants.base import Measurement, Plant

__all__ = ["Measurement", "Plant"]
