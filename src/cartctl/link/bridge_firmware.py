"""The bridge sketch's logic (``firmware/cartctl_bridge/bridge_logic.h``) in Python, for the virtual cart.

Both implement one contract (``docs/serial-protocol.md``); a test runs them on the same input and
compares them tick by tick, so keep them in sync. Bridge version 2: the 10 ms thread drains the
serial port, runs ``io()`` (writes the stored voltage, reads the encoders), then ``control()``
(:meth:`BridgeFirmware.control`) and sends one GPIO; the 1 ms thread drains as well. After each
drain the held channels go to :meth:`BridgeFirmware.receive`, and :attr:`BridgeFirmware.command_v`
is the voltage of the next ``io()``: the host's newest command acts one tick after the measurement
it answers. The requested voltages apply while drive is 1 and the host sequence number keeps
changing (a request that is not finite counts as 0 V); no new sequence number for
:data:`WATCHDOG_MS` (checked at every drain and ``control()``) trips the watchdog: zero volts until
a new one arrives.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import astuple, dataclass

from cartctl.link.bridge import (
    BRIDGE_VERSION,
    SEQ_WINDOW,
    STATUS_DRIVING,
    STATUS_WATCHDOG,
    WATCHDOG_MS,
    CartSample,
)
from cartctl.link.bridge import SEQ_MODULO as TICK_MODULO
from cartctl.link.dialect import GPIO_FLOAT_COUNT, GPIO_INT_COUNT

__all__ = ["STATUS_DRIVING", "STATUS_WATCHDOG", "TICK_MODULO", "WATCHDOG_MS", "CartIO"]


@dataclass(frozen=True, slots=True)
class CartIO:
    """What ``io()`` read at this tick (rad/s, rad) and wrote to the H-bridges (V)."""

    speed_a_rad_s: float
    speed_b_rad_s: float
    applied_a_v: float
    applied_b_v: float
    position_a_rad: float
    position_b_rad: float


class HeldChannels:
    """The GPIO channels a cart firmware holds, as microOS keeps them for ``control()``.

    ``in_*``: those of the host's last GPIO, held until the next; ``out_*``: those the last
    ``control()`` wrote, which microOS sends; ``tick``: the firmware's tick counter.
    """

    def reset_channels(self) -> None:
        """Power-on state of the channels: every one 0, and the tick 0."""
        self.in_floats: list[float] = [0.0] * GPIO_FLOAT_COUNT
        self.in_ints: list[int] = [0] * GPIO_INT_COUNT
        self.out_floats: list[float] = [0.0] * GPIO_FLOAT_COUNT
        self.out_ints: list[int] = [0] * GPIO_INT_COUNT
        self.tick = 0

    def hold(self, floats: Sequence[float], ints: Sequence[int]) -> None:
        """Overwrite every input channel with those of a GPIO from the host."""
        self.in_floats = [float(v) for v in floats]
        self.in_ints = [int(v) for v in ints]


class BridgeFirmware(HeldChannels):
    """``control()`` of the bridge sketch and the GPIO channels it holds (pure, no I/O)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Power-on state: every channel 0, tripped until the host's first frame."""
        self.reset_channels()
        self._last_seq = 0
        self._last_new_ms = 0
        self._seen = False
        self.frames_lost = 0
        """Host sequence numbers skipped since power-on (modulo 32768)."""
        self.driving = False
        self.tripped = True
        self.command_v: tuple[float, float] = (0.0, 0.0)
        """What the next ``io()`` applies (V), as decided at the last drain or ``control()``."""
        self.command_seq = 0
        """The host sequence number :attr:`command_v` came with."""

    def _decide(self, now_ms: int) -> None:
        """What the next ``io()`` applies, from the held channels and the watchdog at ``now_ms``."""
        age_ms = ((int(now_ms) & 0xFFFFFFFF) - self._last_new_ms) & 0xFFFFFFFF
        self.tripped = not self._seen or age_ms >= WATCHDOG_MS
        self.driving = self.in_ints[1] == 1 and not self.tripped
        finite = [v if math.isfinite(v) else 0.0 for v in self.in_floats[:2]]
        self.command_v = (finite[0], finite[1]) if self.driving else (0.0, 0.0)
        self.command_seq = self.in_ints[0]

    def receive(self, floats: Sequence[float], ints: Sequence[int], now_ms: int) -> None:
        """After a drain: the held channels from the host's last GPIO, seen at ``now_ms``.

        A sequence number that differs from the last one is a new frame: it feeds the watchdog,
        and the numbers skipped in between count as lost, unless the jump is backwards or beyond
        :data:`~cartctl.link.bridge.SEQ_WINDOW` (a new host process).
        """
        self.hold(floats, ints)
        seq = self.in_ints[0]
        if seq != self._last_seq:
            step = (seq - self._last_seq) % TICK_MODULO
            if self._seen and step <= SEQ_WINDOW:
                self.frames_lost = (self.frames_lost + step - 1) % TICK_MODULO
            self._last_seq = seq
            self._last_new_ms = int(now_ms) & 0xFFFFFFFF
            self._seen = True
        self._decide(now_ms)

    def control(self, io: CartIO, now_ms: int) -> tuple[float, float]:
        """One ``control()`` at ``now_ms``, after ``io()`` applied :attr:`command_v`.

        Fills the output channels (the echo is the applied command's sequence number), checks the
        watchdog again, and returns the voltages (V) for the next ``io()`` (a later drain may
        replace them with a newer command's).
        """
        applied_seq = self.command_seq  # nothing drains between io() and control()
        self._decide(now_ms)
        status = (applied_seq, self.tick, self.driving, self.tripped, self.frames_lost)
        fields = (now_ms, *astuple(io), *status, BRIDGE_VERSION)  # in CartSample's order
        floats, ints = CartSample(*fields).to_channels()
        self.out_floats, self.out_ints = list(floats), list(ints)
        self.tick = (self.tick + 1) % TICK_MODULO
        return self.command_v
