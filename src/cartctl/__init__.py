"""cartctl: identify, design and run velocity control of a two-wheeled DC-motor cart.

Pipeline: ``data`` → ``identify`` → ``models/`` → ``design`` → ``controllers/`` →
``runtime`` (plant, estimator, controller, sinks) → ``logs/`` → review.

From Python: ``cartctl.load_trace``, ``excite``, ``identify``, ``load_model``, ``save_model``,
``design_pi``, ``design_poles`` and ``simulate`` (see :mod:`cartctl.api`).
"""

__version__ = "0.1.0"

_API = ("load_trace", "excite", "identify", "load_model", "save_model", "design_pi",
        "design_poles", "simulate")  # fmt: skip

__all__ = ["TS_S", "__version__", *_API]


def __getattr__(name: str) -> object:
    """The Python API (:mod:`cartctl.api`) and ``TS_S``, imported on first use: ``import cartctl``
    imports nothing, so the command line routes its stop signals before any other import runs."""
    if name == "TS_S":
        from cartctl.cart import PERIOD_S

        return PERIOD_S
    if name in _API:
        from cartctl import api

        return getattr(api, name)
    raise AttributeError(f"module 'cartctl' has no attribute {name!r}")
