"""What the command line offers, by name: limits, defaults and the names of choices.

The parser is built from these before any command runs, so this module imports nothing heavy
(``cartctl --help`` loads no numpy or scipy). The modules that implement them import them from
here: :mod:`cartctl.signals` (the excitation signals, the longest run), :mod:`cartctl.reference`
(the reference specifications), :mod:`cartctl.plants.factory` (the sim plant's model) and
:mod:`cartctl.link.cart_link` (the wait for a cart).

The shipped model and controller files, :data:`SHIPPED_FILES` by name, are found by
:func:`find_file` from any folder: the working folder first, then the copies installed with the
package (``cartctl/shipped/``, put there by ``setup.py`` when the wheel is built), then the source
checkout the package runs from (an editable install). Other files in ``models/`` and
``controllers/`` are the user's: never packed, and found only where they are.
"""

from __future__ import annotations

from pathlib import Path
from types import MappingProxyType

__all__ = [
    "DEFAULT_CONNECT_TIMEOUT_S",
    "DEFAULT_MODEL",
    "FORMS",
    "MAX_DURATION_S",
    "MAX_TUNE_SETTINGS",
    "SHIPPED_FILES",
    "SHIPPED_FOLDERS",
    "SIGNALS",
    "find_file",
]

MAX_DURATION_S = 24 * 3600.0
"""The longest signal, run or recording cartctl takes: 24 h (8.64 million ticks of 10 ms)."""

MAX_TUNE_SETTINGS = 1_000
"""The largest ``cartctl tune --grid`` (settings): a setting is designed and run in about 50 ms
on one core, so a grid this size is about a minute of work per core (the default grids have 42)."""

SIGNALS = ("square", "step", "prbs", "multisine", "chirp")
"""Names accepted by :func:`cartctl.signals.make_signal` (and ``cartctl excite --signal``)."""

FORMS = "step:A[:DELAY_S], square:A:PERIOD_S, ramp:SLOPE[:LIMIT], const:A or file:PATH"
"""The reference specifications :mod:`cartctl.reference` reads, for help texts and messages."""

DEFAULT_MODEL = Path("models/ground.toml")
"""The model file of the sim plant (and of designs) when none is given."""

DEFAULT_CONNECT_TIMEOUT_S = 5.0
"""The wait for a cart's first HEARTBEAT (s). Opening the port resets the Mega (DTR); its
bootloader takes 1-2 s before the first HEARTBEAT."""

SHIPPED_FILES = MappingProxyType({
    "models": ("air.toml", "ground-timing.toml", "ground.toml"),
    "controllers": ("pi.toml", "poles.toml", "serial-pi.toml", "serial-poles.toml"),
})  # fmt: skip
"""The files shipped with cartctl, by folder: the only ones the wheel packs (``setup.py`` reads
this list) and :func:`find_file` finds outside the working folder. A new shipped file is added
here (tests/test_shipped_files.py checks the list against the files git tracks)."""

SHIPPED_FOLDERS = tuple(SHIPPED_FILES)
"""The folders of files shipped with cartctl, as named in the repository and the package."""


def _shipped_roots() -> tuple[Path, ...]:
    package = Path(__file__).resolve().parent
    roots = [package / "shipped"]  # an installed wheel
    checkout = package.parents[1]  # src/cartctl/ -> the repository (an editable install)
    if (checkout / "pyproject.toml").is_file() and (checkout / "src" / "cartctl").is_dir():
        roots.append(checkout)
    return tuple(roots)


def find_file(path: str | Path) -> Path:
    """``path`` if it exists; else, for a shipped file's relative path, the shipped file.

    ``controllers/pi.toml`` names the file in the working folder when there is one, and the
    controller shipped with cartctl otherwise. Other paths (a user's ``models/mine.toml``) are
    returned as given, in a wheel and an editable install alike (a missing one is reported by
    whoever opens it).
    """
    given = Path(path)
    if given.exists() or given.is_absolute() or len(given.parts) != 2:
        return given
    folder, name = given.parts
    if name not in SHIPPED_FILES.get(folder, ()):
        return given
    for root in _shipped_roots():
        candidate = root / given
        if candidate.is_file():
            return candidate
    return given
