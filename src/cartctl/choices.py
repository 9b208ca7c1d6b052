"""What the command line offers by name (limits, defaults, choices), and the shipped files.

The parser is built from these before any command runs, so this module imports nothing heavy
(``cartctl --help`` loads no numpy or scipy).
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, TypeGuard

if TYPE_CHECKING:
    import numpy as np

MAX_DURATION_S = 24 * 3600.0
"""The longest signal, run or recording cartctl takes: 24 h (8.64 million ticks of 10 ms)."""


def is_whole(value: object) -> TypeGuard[int | np.integer]:
    """True for a Python or numpy integer; False for anything else, booleans included (numpy's
    integers are ``numbers.Integral``: no numpy import here)."""
    return isinstance(value, Integral) and not isinstance(value, bool)


def is_number(value: object) -> TypeGuard[float]:
    """True for a real number, numpy's too; False for a bool, text, None …"""
    return isinstance(value, Real) and not isinstance(value, bool)


def as_float(value: float) -> float:
    """``float(value)``; inf for a whole number beyond any float."""
    try:
        return float(value)
    except OverflowError:
        return math.inf


def check_finite(value: float, option: str) -> float:
    """``value`` if it is a finite number; else one line: ``OPTION must be a number, got nan``
    (or text, None, a bool: no number)."""
    from cartctl.errors import InputError  # here: setup.py reads this file without the package

    if not is_number(value):  # (from Python: the API)
        raise InputError(f"{option} must be a number, got {value!r}")
    number = as_float(value)
    if math.isnan(number):
        raise InputError(f"{option} must be a number, got nan")
    if math.isinf(number):
        raise InputError(f"{option} must be finite, got {number:g}")
    return value


def check_duration(seconds: float, option: str = "--duration") -> float:
    """``seconds`` if in (0, :data:`MAX_DURATION_S`]; else one line naming ``option``."""
    from cartctl.errors import InputError  # here: setup.py reads this file without the package

    number = is_number(seconds)
    if not (number and 0.0 < seconds <= MAX_DURATION_S):  # (NaN and inf fail the range too)
        shown = (
            f"{seconds:g}" if isinstance(seconds, float) else seconds if number else repr(seconds)
        )
        raise InputError(
            f"{option} must be a positive number of seconds up to {MAX_DURATION_S:g} (24 h), "
            f"got {shown}"
        )
    return seconds


MAX_TUNE_SETTINGS = 1_000
"""The largest ``cartctl tune --grid``: about a minute of work per core at 50 ms a setting."""

SIGNALS = ("square", "step", "prbs", "multisine", "chirp")
"""Names accepted by :func:`cartctl.signals.make_signal` (and ``cartctl excite --signal``)."""

FORMS = "step:A[:DELAY_S], square:A:PERIOD_S, ramp:SLOPE[:LIMIT], const:A or file:PATH"
"""The reference specifications :mod:`cartctl.reference` reads, for help texts and messages."""

DEFAULT_MODEL = Path("models/ground.toml")
"""The model file of the sim plant (and of designs) when none is given."""

DEFAULT_CONNECT_TIMEOUT_S = 5.0
"""The wait for a cart's first HEARTBEAT (s); the Mega's bootloader takes 1-2 s after the reset."""

SHIPPED_FILES = MappingProxyType({
    "models": ("air.toml", "ground-timing.toml", "ground.toml"),
    "controllers": ("pi.toml", "poles.toml", "serial-pi.toml", "serial-poles.toml"),
})  # fmt: skip
"""The files shipped with cartctl, by folder: the only ones the wheel packs (``setup.py`` reads
this list) and :func:`find_file` finds outside the working folder; other files are the user's."""

SHIPPED_FOLDERS = tuple(SHIPPED_FILES)


def _shipped_roots() -> tuple[Path, ...]:
    package = Path(__file__).resolve().parent
    roots = [package / "shipped"]  # an installed wheel
    checkout = package.parents[1]  # src/cartctl/ -> the repository (an editable install)
    if (checkout / "pyproject.toml").is_file() and (checkout / "src" / "cartctl").is_dir():
        roots.append(checkout)
    return tuple(roots)


def find_file(path: str | Path) -> Path:
    """``path`` if it exists; for a shipped file's relative path, else the copy installed with
    the package (``cartctl/shipped/``) or in the checkout it runs from; else ``path`` as given."""
    given = Path(path)
    folder, name = given.parts if len(given.parts) == 2 else ("", "")
    if given.exists() or given.is_absolute() or name not in SHIPPED_FILES.get(folder, ()):
        return given
    for root in _shipped_roots():
        candidate = root / given
        if candidate.is_file():
            return candidate
    return given
