"""Files and formats: traces and their meta files (``trace``, ``read``, ``columns``), model
files (``modelfile``) and the TOML files' format lines (``tomlfile``); imports nothing."""
