"""Files and formats: what cartctl reads and writes on disk.

- :mod:`cartctl.data.trace`: the :class:`~cartctl.data.trace.Trace` (the trace columns) and
  :func:`~cartctl.data.trace.write_trace`;
- :mod:`cartctl.data.read`: :func:`~cartctl.data.read.read_trace`, trace CSV and
  QRoboticsCenter logs to a trace, with the checks of what the numbers mean;
- :mod:`cartctl.data.table`: a file's numbers, with errors that name line, row and column;
- :mod:`cartctl.data.columns`: which file column or QRC label becomes which trace column;
- :mod:`cartctl.data.qrc`: the QRoboticsCenter log formats;
- :mod:`cartctl.data.tracemeta`: the meta file beside a trace (its plant and loop delay);
- :mod:`cartctl.data.tomlfile`: the TOML files' format lines and versions;
- :mod:`cartctl.data.modelfile`: model files (the ARX models of both motors).

The package imports nothing: the command line's parser takes the formats' names from
:mod:`cartctl.data.tomlfile` without loading numpy.
"""
