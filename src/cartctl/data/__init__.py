"""Files and formats: traces (``trace``, ``read``, ``columns``, ``qrc``, ``tracemeta``), model
files (``modelfile``) and the TOML files' format lines (``tomlfile``).

The package imports nothing: the parser takes the formats' names without loading numpy.
"""
