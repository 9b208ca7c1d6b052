"""Files and formats: traces and their meta files (``trace``, ``read``, ``columns``), model
files (``modelfile``), the TOML files' format lines (``tomlfile``) and the checks of output
paths (``outputs``); imports nothing."""
