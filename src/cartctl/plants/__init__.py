"""Plants: what experiments and the loop drive, one tick at a time (docs/plants.md)."""

from cartctl.plants.base import Measurement, Plant
from cartctl.plants.factory import make_plant

__all__ = ["Measurement", "Plant", "make_plant"]
