"""Identification: motor models from recorded experiments (the report's ARX method and beyond),
their diagnostics, validation and the ``identify --report`` figures."""
