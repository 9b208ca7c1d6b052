"""cartctl's firmwares in Python: how a cart says which it runs (float 6, docs/serial-protocol.md
§3.1), the bridge sketch's logic (``firmware/cartctl_bridge/bridge_logic.h``: a test compares them
tick by tick) and the exported on-board ``control()`` (``controlEnabled()`` not modelled).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import astuple, dataclass

import cartctl.link.bridge as bridge
from cartctl.cart import PERIOD_S
from cartctl.choices import MAX_DURATION_S
from cartctl.data.trace import MOTORS
from cartctl.errors import InputError
from cartctl.link.dialect import GPIO_FLOAT_COUNT, GPIO_INT_COUNT, check_gpio_counts
from cartctl.reference import ReferenceSchedule
from cartctl.runtime.base import Controller

CHANNEL_KEYS: tuple[str, ...] = (
    *(f"f{i}" for i in range(GPIO_FLOAT_COUNT)),
    *(f"i{i}" for i in range(GPIO_INT_COUNT)),
)
"""A GPIO's channels in frame order: float channels f0..f7, then int channels i0..i3."""
CH_FIRMWARE_ID = bridge.CH_BRIDGE_VERSION
"""The float channel in which cartctl's firmware says which it is (the bridge's version)."""
ONBOARD_LAYOUT = 1
ONBOARD_ID = 1000 + ONBOARD_LAYOUT  # the on-board export's marker in float 6: 1000 + its layout
# the on-board export's layout 1: references in from the PC, and out from the first channel of
# each group: speeds (rad/s), voltages computed at that tick (V), references (rad/s); A, then B
IN_REFERENCE = {"a": 0, "b": 1}
OUT_SPEED, OUT_VOLTAGE, OUT_REFERENCE = 0, 2, 4


@dataclass(frozen=True)
class Firmware:
    """One of cartctl's firmwares: its name, and (channel key, label) of the channels it fills."""

    name: str
    labels: tuple[tuple[str, str], ...]


BRIDGE = Firmware(
    f"cartctl bridge version {bridge.BRIDGE_VERSION}",
    (
        *((f"f{i}", label) for i, label in enumerate(bridge.SAMPLE_FLOATS)),
        *((f"i{i}", label) for i, label in enumerate(bridge.SAMPLE_INTS)),
    ),
)
"""The bridge sketch of version :data:`~cartctl.link.bridge.BRIDGE_VERSION`."""
_ONBOARD_OUT = {"speed": OUT_SPEED, "voltage": OUT_VOLTAGE, "reference": OUT_REFERENCE}
ONBOARD = Firmware(
    f"cartctl on-board controller ('cartctl export --arduino', layout {ONBOARD_LAYOUT})",
    (
        *(
            (f"f{first + i}", f"{what}_{m}")
            for what, first in _ONBOARD_OUT.items()
            for i, m in enumerate(IN_REFERENCE)
        ),
        (f"f{CH_FIRMWARE_ID}", "firmware_id"),
    ),
)
"""A controller of ``cartctl export --arduino`` on the cart (layout :data:`ONBOARD_LAYOUT`)."""


def recognise_firmware(floats: Sequence[float], ints: Sequence[int]) -> Firmware | None:
    """Which of cartctl's firmwares sent a GPIO with these channels (by float
    :data:`CH_FIRMWARE_ID`), or None. Raises ValueError unless there are 8 floats and 4 ints."""
    check_gpio_counts(floats, ints)
    marker = floats[CH_FIRMWARE_ID]
    return {float(bridge.BRIDGE_VERSION): BRIDGE, float(ONBOARD_ID): ONBOARD}.get(marker)


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
    """The GPIO channels a firmware holds as microOS keeps them: ``in_*`` from the host's last
    GPIO, ``out_*`` as the last ``control()`` wrote them (microOS sends those), and a tick."""

    def reset_channels(self) -> None:
        """Power-on state of the channels: every one 0, and the tick 0."""
        self.in_floats: list[float] = [0.0] * GPIO_FLOAT_COUNT
        self.in_ints: list[int] = [0] * GPIO_INT_COUNT
        self.out_floats: list[float] = [0.0] * GPIO_FLOAT_COUNT
        self.out_ints: list[int] = [0] * GPIO_INT_COUNT
        self.tick = 0

    def receive(self, floats: Sequence[float], ints: Sequence[int], now_ms: int = 0) -> None:
        """After a drain: every input channel from the host's last GPIO."""
        self.in_floats = [float(v) for v in floats]
        self.in_ints = [int(v) for v in ints]


class BridgeFirmware(HeldChannels):
    """``control()`` of the bridge sketch and the GPIO channels it holds (pure, no I/O)."""

    ready_text = "cartctl bridge ready"

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Power-on state: every channel 0, tripped until the host's first frame."""
        self.reset_channels()
        self._last_seq = 0
        self._last_new_ms = 0
        self._seen = False
        self.frames_lost = 0  # host sequence numbers skipped since power-on (modulo 32768)
        self.driving = False
        self.tripped = True
        # what the next io() applies (V), as decided at the last drain or control(), and the host
        # sequence number it came with
        self.command_v: tuple[float, float] = (0.0, 0.0)
        self.command_seq = 0

    def _decide(self, now_ms: int) -> None:
        """What the next ``io()`` applies, from the held channels and the watchdog at ``now_ms``."""
        age_ms = (int(now_ms) - self._last_new_ms) & 0xFFFFFFFF  # u32 ms, wrapping
        self.tripped = not self._seen or age_ms >= bridge.WATCHDOG_MS
        self.driving = self.in_ints[1] == 1 and not self.tripped
        finite = [v if math.isfinite(v) else 0.0 for v in self.in_floats[:2]]
        self.command_v = (finite[0], finite[1]) if self.driving else (0.0, 0.0)
        self.command_seq = self.in_ints[0]

    def receive(self, floats: Sequence[float], ints: Sequence[int], now_ms: int = 0) -> None:
        """After a drain at ``now_ms``: a sequence number that differs from the last one is a new
        frame: it feeds the watchdog, and the numbers skipped in between count as lost, unless the
        jump is backwards or beyond :data:`~cartctl.link.bridge.SEQ_WINDOW` (a new host)."""
        super().receive(floats, ints)
        seq = self.in_ints[0]
        if seq != self._last_seq:
            step = bridge.tick_difference(self._last_seq, seq)
            if self._seen and step <= bridge.SEQ_WINDOW:
                self.frames_lost = (self.frames_lost + step - 1) % bridge.SEQ_MODULO
            self._last_seq = seq
            self._last_new_ms = int(now_ms) & 0xFFFFFFFF
            self._seen = True
        self._decide(now_ms)

    def control(self, io: CartIO, now_ms: int) -> tuple[float, float]:
        """One ``control()`` at ``now_ms``, after ``io()`` applied :attr:`command_v`: fills the
        output channels (echoing the applied command), checks the watchdog again, and returns the
        voltages (V) for the next ``io()`` (a later drain may replace them)."""
        applied_seq = self.command_seq  # nothing drains between io() and control()
        self._decide(now_ms)
        status = (applied_seq, self.tick, self.driving, self.tripped, self.frames_lost)
        fields = (now_ms, *astuple(io), *status, bridge.BRIDGE_VERSION)  # CartSample's order
        floats, ints = bridge.CartSample(*fields).to_channels()
        self.out_floats, self.out_ints = list(floats), list(ints)
        self.tick = bridge.next_seq(self.tick)
        return self.command_v


MAX_TICKS = round(MAX_DURATION_S / PERIOD_S)  # a reference spec covers the longest run (24 h)


class OnboardFirmware(HeldChannels):
    """``control()`` running a runtime controller per motor ('a', 'b'; none: 0 V) on the cart;
    ``reference`` is both motors' reference spec (None: the held input channels)."""

    ready_text = "cartctl on-board controller ready"

    def __init__(
        self,
        controllers: Mapping[str, Controller],
        *,
        reference: str | None = None,
    ) -> None:
        unknown = sorted(set(controllers) - set(MOTORS))
        if unknown:
            raise InputError(f"the cart has motors a and b, not {', '.join(unknown)}")
        self.controllers = dict(controllers)
        self._schedules: dict[str, ReferenceSchedule] = {}
        if reference is not None:  # else the held input channels
            self._schedules = {
                m: ReferenceSchedule(reference, MAX_TICKS, motor=m) for m in controllers
            }
        self.reset()

    def reset(self) -> None:
        """Power-on state: channels 0, controllers at rest, tick 0."""
        self.reset_channels()
        for controller in self.controllers.values():
            controller.reset()

    def reference_at(self, motor: str) -> float:
        """The reference (rad/s) of ``motor`` at the current tick."""
        if self._schedules:
            return self._schedules[motor][min(self.tick, MAX_TICKS - 1)]
        return self.in_floats[IN_REFERENCE[motor]]

    def control(self, io: CartIO, now_ms: int = 0) -> tuple[float, float]:
        """One ``control()`` call: returns the voltages (V) for the next tick's ``io()``."""
        out = [0.0] * GPIO_FLOAT_COUNT
        out[CH_FIRMWARE_ID] = float(ONBOARD_ID)
        voltage = [0.0, 0.0]
        speeds = (io.speed_a_rad_s, io.speed_b_rad_s)
        for i, (motor, measured) in enumerate(zip(MOTORS, speeds, strict=True)):
            if (controller := self.controllers.get(motor)) is not None:
                reference = self.reference_at(motor)
                voltage[i] = controller.step(reference, measured)
                out[OUT_SPEED + i], out[OUT_VOLTAGE + i] = measured, voltage[i]
                out[OUT_REFERENCE + i] = reference
        self.out_floats = out
        self.tick += 1
        return voltage[0], voltage[1]
