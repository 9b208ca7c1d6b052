"""Figures of merit, and how they print: pure numbers, shared by identification, design, the run
summary and tuning.

- :mod:`cartctl.measures.metrics`: fit percentages and the other figures of a model against data;
- :mod:`cartctl.measures.stepinfo`: the step metrics of a response (overshoot, rise and settling
  time, the settling band), of one run or of many;
- :mod:`cartctl.measures.numfmt`: numbers for the terminal, one rounding per table column (no
  numpy: the parser's modules may import it).
"""
