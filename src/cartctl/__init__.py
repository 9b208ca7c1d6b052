"""cartctl: identify, design and run velocity control of a two-wheeled DC-motor cart.

Pipeline: ``data`` → ``identify`` → ``models/`` → ``design`` → ``controllers/`` →
``runtime`` (plant, estimator, controller, sinks) → ``logs/`` → review.
"""

from cartctl.cart import PERIOD_S as TS_S

__version__ = "0.1.0"

__all__ = ["TS_S", "__version__"]
