"""Identification: from recorded experiments to motor models (the report's method and beyond).

``arx`` least squares with parameter uncertainty, ``delay`` estimation, Butterworth ``prefilter``,
output-error refinement (``oe``), cycle averaging and empirical transfer functions (``etfe``),
validation against measured data (``validate``), the superposition test (``linearity``), and the
figures and summary of ``cartctl identify --report`` (``report``).
"""
