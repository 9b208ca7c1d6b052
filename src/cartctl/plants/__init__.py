"""Plants: what experiments and the loop drive, one tick at a time.

``sim`` (:mod:`cartctl.plants.sim`, the ARX models of a model file) and ``physics``
(:mod:`cartctl.plants.physics`, the physical cart simulator); :func:`make_plant` builds one from
its command-line name, the ``virtual`` and ``serial:PORT`` plants from :mod:`cartctl.link`.
"""

from cartctl.plants.base import Measurement, Plant
from cartctl.plants.factory import make_plant

__all__ = ["Measurement", "Plant", "make_plant"]
