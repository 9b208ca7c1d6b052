"""The options of a virtual cart (``--plant virtual:KEY=VALUE,...``, ``virtual-cart --faults``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from cartctl.errors import InputError

LATE_STRETCH_TICKS = 5
"""With ``late``, the cart takes the host's commands a tick late in stretches of this many ticks."""

RECEIVE_SCHEDULES = {"bridge": 1000, "microos": None}
"""Receive schedules: the bridge's drain period (µs), or None for microOS's communication thread
alone (the bridge sketch before it drained the port itself, and a controller on the cart)."""


@dataclass(frozen=True)
class CartFaults:
    """The firmware, timing and faults of a virtual cart.

    Attributes
    ----------
    garbage, corrupt : float
        Fraction of outgoing frames preceded by a burst of 1-16 random bytes, or with one byte
        changed (their CRC fails).
    stall_after_s, pull_after_s : float or None
        This long (s) after the host's first frame the cart stalls (no ticks, nothing sent, port
        open), or the cable is pulled (the port vanishes).
    generation : str
        'a' (MAVLink 1, GPIO: the bridge sketch) or 'b' (MAVLink 2, GPIOX, which cartctl refuses).
    reply_jitter_ms : float
        Each write of the host reaches the line a random 0 .. this many ms late.
    receive : str
        'bridge' (the sketch drains the port every 1 ms and before io()) or 'microos' (microOS's
        communication thread alone, once per tick: the sketch before).
    bridge : int
        The sketch's version: 2 (500 kbaud, the newest command at the next io(): loop delay 1) or
        1 (115200 baud, the voltage stored at control(): loop delay 3).
    usb : bool
        Model the Mega's ATmega16U2 USB bridge (the cart's frames reach the PC up to ~5 ms late,
        the PC's within 1 ms); ``usb=off`` is a bare pseudo-terminal.
    actuation_ms : float or None
        When a command lands after its tick in the simulated wheels (ms, (0, 10]); None: the
        preset's calibrated 3 ms.
    reverse_a, reverse_b : bool
        That motor's leads swapped (a wiring fault for ``cartctl commission`` to find).
    late : float
        Fraction of ticks (in [0, 1]) at which the host's commands arrive a tick late, in stretches
        of :data:`LATE_STRETCH_TICKS` (:meth:`late_at`): there the echoes show a loop delay one
        tick longer, and at a stretch's end one command is overtaken by the next.
    """

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

    KEYS = ("garbage", "corrupt", "stall", "pull", "generation", "reply_jitter_ms", "receive",
            "bridge", "usb", "actuation_ms", "reverse_a", "reverse_b", "late")  # fmt: skip

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
        """Faults from ``key=value,...``.

        Keys: garbage=0.05, corrupt=0.05, stall=S, pull=S, generation=b, reply_jitter_ms=3,
        receive=microos, bridge=1, usb=off, actuation_ms=10, reverse_b=1, late=0.3.
        """
        faults = cls()
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, raw = item.partition("=")
            key, value = key.strip(), raw.strip().lower()
            if not sep or key not in cls.KEYS:
                raise InputError(
                    f"bad virtual cart option '{item}'; expected key=value with key in "
                    f"{', '.join(cls.KEYS)}"
                )
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
                    if key == "actuation_ms":
                        raise InputError(
                            f"actuation_ms needs a number of ms in (0, 10], got '{raw}'"
                        ) from None
                    raise InputError(f"fault '{key}' needs a number, got '{raw}'") from None
            field = {"stall": "stall_after_s", "pull": "pull_after_s"}.get(key, key)
            faults = replace(faults, **{field: parsed})
        return faults


_FLAG = {"0": False, "1": True}
_CHOICES: dict[str, dict[str, Any]] = {
    "usb": {"on": True, "off": False},
    "reverse_a": _FLAG,
    "reverse_b": _FLAG,
    "bridge": {"1": 1, "2": 2},
}
