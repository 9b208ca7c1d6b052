"""Strict JSON for every ``--json`` output: NaN and infinities become ``null`` (Python's ``NaN``
and ``Infinity`` are not JSON), numpy values plain numbers and lists."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["dumps", "strict"]


def strict(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None and numpy types made plain."""
    if isinstance(value, float | np.floating):
        number = float(value)
        return number if math.isfinite(number) else None
    if isinstance(value, np.generic | np.ndarray):  # numpy's own: plain Python values and lists
        return strict(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict(v) for v in value]
    return value


def dumps(value: Any) -> str:
    """Strict JSON text of ``value`` (see :func:`strict`)."""
    return json.dumps(strict(value), allow_nan=False)
