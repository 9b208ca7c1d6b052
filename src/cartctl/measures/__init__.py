"""Figures of merit and how they print: fits (``metrics``), step metrics (``stepinfo``), numbers
for the terminal (``numfmt``, no numpy, so the parser may import it)."""
