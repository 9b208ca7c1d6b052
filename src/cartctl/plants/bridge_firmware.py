"""The bridge sketch's per-tick logic (``firmware/cartctl_bridge``), in Python, for the virtual cart.

The sketch on the cart and this class implement one contract (``docs/serial-protocol.md`` §3), and
a test runs both on the same input and compares them tick by tick, so keep them in sync.

microOS calls, every 10 ms: ``io()`` (writes the voltage stored at the previous tick, reads the
encoders), then ``control()``; the communication thread then receives every waiting GPIO (which
overwrites the held input channels) and sends one GPIO with the output channels ``control()`` wrote.
This class is ``control()`` and the held input channels:

- the requested voltages (float channels 0 and 1) are applied while drive (int channel 1) is 1 and
  the host sequence number (int channel 0) keeps changing (a request that is not a finite number
  counts as 0 V); after :data:`WATCHDOG_TICKS` ticks
  without a new one, the watchdog trips and the cart applies zero volts until a new frame arrives;
- out go the measured speeds, the voltages on the H-bridges at this tick, the wheel positions, the
  echo of the held sequence number, a tick counter and the status bits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from cartctl.link.bridge import SEQ_MODULO as TICK_MODULO
from cartctl.link.bridge import STATUS_DRIVING, STATUS_WATCHDOG, WATCHDOG_TICKS

__all__ = ["STATUS_DRIVING", "STATUS_WATCHDOG", "TICK_MODULO", "WATCHDOG_TICKS", "BridgeFirmware",
           "CartIO"]  # fmt: skip


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


class BridgeFirmware:
    """``control()`` of the bridge sketch and the GPIO channels it holds (pure, no I/O)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Power-on state: every channel 0, so nothing drives until the host says so."""
        self.in_floats: list[float] = [0.0] * 8
        self.in_ints: list[int] = [0] * 4
        self.out_floats: list[float] = [0.0] * 8
        self.out_ints: list[int] = [0] * 4
        self.tick = 0
        self._last_seq = 0
        self._stale_ticks = WATCHDOG_TICKS  # tripped until the host's first frame

    def receive(self, floats: Sequence[float], ints: Sequence[int]) -> None:
        """A GPIO from the host: every input channel is overwritten and then held."""
        self.in_floats = [float(v) for v in floats]
        self.in_ints = [int(v) for v in ints]

    def control(self, io: CartIO) -> tuple[float, float]:
        """One ``control()`` call: returns the voltages (V) for the next tick's ``io()``."""
        seq = self.in_ints[0]
        if seq != self._last_seq:
            self._last_seq = seq
            self._stale_ticks = 0
        elif self._stale_ticks < WATCHDOG_TICKS:
            self._stale_ticks += 1
        tripped = self._stale_ticks >= WATCHDOG_TICKS
        driving = self.in_ints[1] == 1 and not tripped
        voltage_a = _finite_or_zero(self.in_floats[0]) if driving else 0.0
        voltage_b = _finite_or_zero(self.in_floats[1]) if driving else 0.0
        self.out_floats = [
            io.speed_a_rad_s, io.speed_b_rad_s, io.applied_a_v, io.applied_b_v,
            io.position_a_rad, io.position_b_rad, 0.0, 0.0,
        ]  # fmt: skip
        status = (STATUS_DRIVING if driving else 0) | (STATUS_WATCHDOG if tripped else 0)
        self.out_ints = [seq, self.tick, status, 0]
        self.tick = (self.tick + 1) % TICK_MODULO
        return voltage_a, voltage_b
