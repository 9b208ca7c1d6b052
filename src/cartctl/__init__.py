"""cartctl: identify, design and run velocity control of a two-wheeled DC-motor cart.

The Python API (:mod:`cartctl.api`) is importable from here.
"""

__version__ = "0.1.0"

_API = ("load_trace", "excite", "identify", "load_model", "save_model", "design_pi",
        "design_poles", "simulate")  # fmt: skip

__all__ = ["TS_S", "__version__", *_API]


def __getattr__(name: str) -> object:
    """The API and ``TS_S`` on first use: the command line routes its stop signals first."""
    if name == "TS_S":
        from cartctl.cart import PERIOD_S

        return PERIOD_S
    if name in _API:
        from cartctl import api

        return getattr(api, name)
    raise AttributeError(f"module 'cartctl' has no attribute {name!r}")
