"""Decoded microOS messages, as plain frozen dataclasses.

Every message carries the frame's header fields ``seq``, ``sysid`` and ``compid`` last, with
defaults, so that tests and simulators can build messages without a frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

__all__ = [
    "BUTTON_COUNT",
    "BUTTON_EVENT_BASE",
    "Event",
    "GenerationBFrame",
    "Gpio",
    "Heartbeat",
    "Message",
    "PrintText",
    "ThreadInfo",
]

BUTTON_EVENT_BASE = 1000
"""EVENT type of QRC's button 0; buttons 0..7 are 1000..1007."""
BUTTON_COUNT = 8


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """HEARTBEAT (id 0): the cart's sign of life, every 1.1 s."""

    time_ms: int
    type: int
    data: bytes
    mavlink_version: int
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class Gpio:
    """GPIO (id 3): 8 float and 4 int channels, in either direction."""

    time_ms: int
    floats: tuple[float, ...]
    """The 8 float channels (float32 values)."""
    ints: tuple[int, ...]
    """The 4 int channels (int32 values)."""
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class Event:
    """EVENT (id 4), e.g. a QRC button press."""

    type: int
    seq: int = 0
    sysid: int = 0
    compid: int = 0

    @property
    def button(self) -> int | None:
        """The QRC button 0..7 this event stands for, or None for another event type."""
        index = self.type - BUTTON_EVENT_BASE
        return index if 0 <= index < BUTTON_COUNT else None


@dataclass(frozen=True, slots=True)
class PrintText:
    """PRINT (id 5): up to 32 bytes of firmware text, NUL padding stripped.

    Lines end with "\\r\\n" and may be split over frames; see :class:`cartctl.link.LineAssembler`.
    """

    text: str
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class ThreadInfo:
    """THREAD_INFO (id 1): a firmware thread's timing report; its 22 bytes are not interpreted."""

    payload: bytes
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class GenerationBFrame:
    """A valid MAVLink 2 frame of a generation-B cart (only GPIOX, id 14, is recognised)."""

    msgid: int
    seq: int = 0
    sysid: int = 0
    compid: int = 0


Message: TypeAlias = Heartbeat | Gpio | Event | PrintText | ThreadInfo | GenerationBFrame
"""Any decoded message; usable with ``isinstance``."""
