"""The bridge sketch's logic (``firmware/cartctl_bridge/bridge_logic.h``), in Python, for the virtual cart.

The sketch on the cart and this class implement one contract (``docs/serial-protocol.md``), and a
test runs both on the same input and compares them tick by tick, so keep them in sync.

The sketch drains the serial port every 1 ms from its own microOS thread and once more right
before each ``control()``; after each drain it hands the channels microOS holds from the host's last
GPIO to :meth:`BridgeFirmware.receive`, with the time. Every 10 ms microOS runs ``io()`` (writes
the voltage stored at the previous tick, reads the encoders), then ``control()``, which is
:meth:`BridgeFirmware.control`:

- the requested voltages (float channels 0 and 1) are applied while drive (int channel 1) is 1 and
  the host sequence number (int channel 0) keeps changing (a request that is not a finite number
  counts as 0 V); when no new sequence number has arrived for :data:`WATCHDOG_MS` at a
  ``control()``, the watchdog trips and the cart applies zero volts until a new one arrives;
- out go the measured speeds, the voltages on the H-bridges at this tick, the wheel positions, the
  echo of the held sequence number, a tick counter, the status bits and the count of host
  sequence numbers the cart never saw (frames lost on the way in).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from cartctl.link.bridge import SEQ_MODULO as TICK_MODULO
from cartctl.link.bridge import SEQ_WINDOW, STATUS_DRIVING, STATUS_WATCHDOG, WATCHDOG_MS
from cartctl.link.dialect import GPIO_FLOAT_COUNT, GPIO_INT_COUNT

__all__ = ["STATUS_DRIVING", "STATUS_WATCHDOG", "TICK_MODULO", "WATCHDOG_MS", "BridgeFirmware",
           "CartIO", "HeldChannels"]  # fmt: skip


@dataclass(frozen=True, slots=True)
class CartIO:
    """What ``io()`` read at this tick and what it wrote to the H-bridges."""

    speed_a_rad_s: float
    speed_b_rad_s: float
    applied_a_v: float
    applied_b_v: float
    position_a_rad: float
    position_b_rad: float


def _finite_or_zero(value: float) -> float:
    return value if math.isfinite(value) else 0.0


class HeldChannels:
    """The GPIO channels a cart firmware holds, as microOS keeps them for ``control()``.

    Attributes
    ----------
    in_floats, in_ints
        The channels of the host's last GPIO, held until the next one arrives.
    out_floats, out_ints
        The channels the last ``control()`` wrote, which microOS sends to the host.
    tick
        The firmware's tick counter.
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

    def receive(self, floats: Sequence[float], ints: Sequence[int], now_ms: int) -> None:
        """After a drain: the held channels from the host's last GPIO, seen at ``now_ms``.

        A sequence number that differs from the last one is a new frame: it feeds the watchdog,
        and the numbers skipped in between count as lost, unless the jump is backwards or beyond
        :data:`~cartctl.link.bridge.SEQ_WINDOW` (a new host process).
        """
        self.hold(floats, ints)
        seq = self.in_ints[0]
        if seq == self._last_seq:
            return
        step = (seq - self._last_seq) % TICK_MODULO
        if self._seen and step <= SEQ_WINDOW:
            self.frames_lost = (self.frames_lost + step - 1) % TICK_MODULO
        self._last_seq = seq
        self._last_new_ms = int(now_ms) & 0xFFFFFFFF
        self._seen = True

    def control(self, io: CartIO, now_ms: int) -> tuple[float, float]:
        """One ``control()`` at ``now_ms``: returns the voltages (V) for the next tick's ``io()``."""
        age_ms = ((int(now_ms) & 0xFFFFFFFF) - self._last_new_ms) & 0xFFFFFFFF
        tripped = not self._seen or age_ms >= WATCHDOG_MS
        driving = self.in_ints[1] == 1 and not tripped
        voltage_a = _finite_or_zero(self.in_floats[0]) if driving else 0.0
        voltage_b = _finite_or_zero(self.in_floats[1]) if driving else 0.0
        self.out_floats = [
            io.speed_a_rad_s, io.speed_b_rad_s, io.applied_a_v, io.applied_b_v,
            io.position_a_rad, io.position_b_rad, 0.0, 0.0,
        ]  # fmt: skip
        status = (STATUS_DRIVING if driving else 0) | (STATUS_WATCHDOG if tripped else 0)
        self.out_ints = [self.in_ints[0], self.tick, status, self.frames_lost]
        self.tick = (self.tick + 1) % TICK_MODULO
        return voltage_a, voltage_b
