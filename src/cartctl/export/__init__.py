"""Designed controllers in other forms: C for the cart's own ``control()`` (``cartctl export``).

Where it sits: after ``design``. A generator takes a
:class:`~cartctl.design.controllerfile.ControllerFile` and returns source text; it does no I/O.
"""

from cartctl.export.arduino import arduino_source

__all__ = ["arduino_source"]
