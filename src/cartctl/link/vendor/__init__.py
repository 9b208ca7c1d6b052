"""Generated code that cartctl ships but did not write: see ``README.md`` in this folder.

:mod:`~cartctl.link.vendor.microos_mavlink` is the output of pymavlink's generator (mavgen) for
``cartctl/link/microos.xml``; do not edit it, regenerate it with ``tools/regenerate_dialect.py``.
"""
