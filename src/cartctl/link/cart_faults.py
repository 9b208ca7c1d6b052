"""The options of a virtual cart (``--plant virtual:KEY=VALUE,...``, ``virtual-cart --faults``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

from cartctl.errors import InputError

LATE_STRETCH_TICKS = 5  # with ``late``, commands reach the cart a tick late in stretches this long

RECEIVE_SCHEDULES = {"bridge": 1000, "microos": None}
"""Receive schedules: the bridge's drain period (µs), or None for microOS's communication thread
alone (the bridge sketch before it drained the port itself, and a controller on the cart)."""


@dataclass(frozen=True)
class CartFaults:
    """The firmware, timing and faults of a virtual cart, with the defaults of a healthy bridge
    cart: the keys :meth:`parse` takes and what each does are docs/serial-protocol.md §8's table.
    ``stall_after_s`` and ``pull_after_s`` count from the host's first frame; ``actuation_ms``
    None is the preset's calibrated 3 ms."""

    garbage: float = 0.0
    corrupt: float = 0.0
    stall_after_s: float | None = None
    pull_after_s: float | None = None
    generation: str = "a"
    reply_jitter_ms: float = 0.0
    receive: str = "bridge"
    bridge: int = 2
    usb: bool = True
    actuation_ms: float | None = None
    reverse_a: bool = False
    reverse_b: bool = False
    late: float = 0.0

    @property
    def reversed_motors(self) -> str:
        """The motors wired backwards ('', 'a', 'b' or 'ab')."""
        return ("a" if self.reverse_a else "") + ("b" if self.reverse_b else "")

    def late_at(self, tick: int) -> bool:
        """Whether the host's commands reach the cart a tick late at cart tick ``tick``."""
        if self.late <= 0.0:
            return False
        every = max(LATE_STRETCH_TICKS, round(LATE_STRETCH_TICKS / self.late))
        return tick % every < LATE_STRETCH_TICKS

    def __post_init__(self) -> None:
        for name in ("garbage", "corrupt", "late"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(f"fault '{name}' must be a fraction in [0, 1], got {value}")
        for name in ("stall_after_s", "pull_after_s"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0.0):
                raise InputError(f"fault time '{name}' must be >= 0 s, got {value}")
        if self.generation not in ("a", "b"):
            raise InputError(f"generation must be 'a' or 'b', got '{self.generation}'")
        if not (math.isfinite(self.reply_jitter_ms) and 0.0 <= self.reply_jitter_ms <= 1000.0):
            raise InputError(
                f"fault 'reply_jitter_ms' must be in [0, 1000] ms, got {self.reply_jitter_ms}"
            )
        if self.bridge not in (1, 2):
            raise InputError(f"virtual cart option 'bridge' must be 1 or 2, got {self.bridge}")
        if self.actuation_ms is not None:
            from cartctl.plants.physics_params import check_actuation_ms

            check_actuation_ms(self.actuation_ms)
        if self.receive not in RECEIVE_SCHEDULES:
            raise InputError(
                f"receive must be one of {', '.join(RECEIVE_SCHEDULES)}, got '{self.receive}'"
            )

    @classmethod
    def parse(cls, text: str) -> CartFaults:
        """Faults from ``key=value,...``, e.g. ``garbage=0.05,stall=2,usb=off,reverse_b=1``."""
        faults, seen = cls(), set()
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, raw = item.partition("=")
            key, value = key.strip(), raw.strip().lower()
            if not sep or key not in _FIELD_OF:
                raise InputError(
                    f"bad virtual cart option '{item}'; expected key=value with key in "
                    f"{', '.join(_FIELD_OF)}"
                )
            if key in seen:
                raise InputError(f"virtual cart option '{key}' is given twice; give it once")
            seen.add(key)
            choices = _CHOICES.get(key)
            parsed: Any = value
            if choices is not None:
                if value not in choices:
                    raise InputError(
                        f"virtual cart option '{key}' must be {' or '.join(choices)}, got '{raw}'"
                    )
                parsed = choices[value]
            elif key not in ("generation", "receive"):
                try:
                    parsed = float(raw)
                except ValueError:
                    what = f"fault '{key}' needs a number"
                    if key == "actuation_ms":
                        what = "actuation_ms needs a number of ms in (0, 10]"
                    raise InputError(f"{what}, got '{raw}'") from None
            faults = replace(faults, **{_FIELD_OF[key]: parsed})
        return faults


_FIELD_OF = {  # option key -> field, in the fields' order
    {"stall_after_s": "stall", "pull_after_s": "pull"}.get(f.name, f.name): f.name
    for f in fields(CartFaults)
}


_FLAG = {"0": False, "1": True}
_CHOICES: dict[str, dict[str, Any]] = {
    "usb": {"on": True, "off": False},
    "reverse_a": _FLAG,
    "reverse_b": _FLAG,
    "bridge": {"1": 1, "2": 2},
}
