"""Experiment traces in and out: the first stage of the pipeline (data → identify → design → run).

- :mod:`cartctl.data.read`: :func:`read_trace`, trace CSV and QRoboticsCenter logs to a
  :class:`~cartctl.trace.Trace`, with the checks of what the numbers mean;
- :mod:`cartctl.data.table`: a file's numbers, with errors that name line, row and column;
- :mod:`cartctl.data.columns`: which file column or QRC label becomes which trace column.

The :class:`~cartctl.trace.Trace` type and :func:`~cartctl.trace.write_trace` live in
:mod:`cartctl.trace` and are importable from here.
"""

from cartctl.data.read import SPACING_TOLERANCE_S, VOLTAGE_READ_LIMIT_V, read_trace
from cartctl.trace import MOTORS, REQUIRED_COLUMNS, Trace, parse_mapping, write_trace

__all__ = [
    "MOTORS",
    "REQUIRED_COLUMNS",
    "SPACING_TOLERANCE_S",
    "VOLTAGE_READ_LIMIT_V",
    "Trace",
    "parse_mapping",
    "read_trace",
    "write_trace",
]
