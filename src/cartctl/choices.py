"""What the command line offers, by name: limits, defaults and the names of choices.

The parser is built from these before any command runs, so this module imports nothing heavy
(``cartctl --help`` loads no numpy or scipy). The modules that implement them import them from
here: :mod:`cartctl.signals` (the excitation signals, the longest run), :mod:`cartctl.reference`
(the reference specifications), :mod:`cartctl.plants.factory` (the sim plant's model) and
:mod:`cartctl.plants.cart_link` (the wait for a cart).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DEFAULT_CONNECT_TIMEOUT_S", "DEFAULT_MODEL", "FORMS", "MAX_DURATION_S", "SIGNALS"]

MAX_DURATION_S = 24 * 3600.0
"""The longest signal, run or recording cartctl takes: 24 h (8.64 million ticks of 10 ms)."""

SIGNALS = ("square", "step", "prbs", "multisine", "chirp")
"""Names accepted by :func:`cartctl.signals.make_signal` (and ``cartctl excite --signal``)."""

FORMS = "step:A[:DELAY_S], square:A:PERIOD_S, ramp:SLOPE[:LIMIT], const:A or file:PATH"
"""The reference specifications :mod:`cartctl.reference` reads, for help texts and messages."""

DEFAULT_MODEL = Path("models/ground.toml")
"""The model file of the sim plant (and of designs) when none is given."""

DEFAULT_CONNECT_TIMEOUT_S = 5.0
"""The wait for a cart's first HEARTBEAT (s). Opening the port resets the Mega (DTR); its
bootloader takes 1-2 s before the first HEARTBEAT."""
