"""Which of cartctl's firmwares a cart runs, told by what it sends, and what its channels carry.

Float channel 6 (:data:`CH_FIRMWARE_ID`) of every GPIO cartctl's firmware sends says which it is:
1..999 the bridge sketch of that version (its channel map, :mod:`cartctl.link.bridge`, is known
for :data:`~cartctl.link.bridge.BRIDGE_VERSION`); ``1000 + n`` a controller of ``cartctl export
--arduino`` on the cart, channel layout n (:data:`ONBOARD_ID`); anything else (0 from the course's
own code or a bridge before version 2) is not cartctl's. The labels are the trace's column names
(``speed_a``, ``voltage_a``, ``reference_a``), so that ``review``, ``validate`` and ``convert``
read a ``cartctl monitor`` trace as it is. Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from cartctl.link.bridge import (
    BRIDGE_VERSION,
    CH_APPLIED_A,
    CH_APPLIED_B,
    CH_BRIDGE_VERSION,
    CH_ECHO,
    CH_HOST_LOST,
    CH_POSITION_A,
    CH_POSITION_B,
    CH_SPEED_A,
    CH_SPEED_B,
    CH_STATUS,
    CH_TICK,
)
from cartctl.link.dialect import GPIO_FLOAT_COUNT, GPIO_INT_COUNT, check_gpio_counts

CHANNEL_KEYS: tuple[str, ...] = (
    *(f"f{i}" for i in range(GPIO_FLOAT_COUNT)),
    *(f"i{i}" for i in range(GPIO_INT_COUNT)),
)
"""A GPIO's channels in frame order: float channels f0..f7, then int channels i0..i3."""
CH_FIRMWARE_ID = CH_BRIDGE_VERSION
"""The float channel in which cartctl's firmware says which it is (the bridge's version)."""
ONBOARD_LAYOUT = 1
ONBOARD_ID = 1000 + ONBOARD_LAYOUT
"""What the on-board export sends in float :data:`CH_FIRMWARE_ID`: 1000 + its layout."""
# the on-board export's layout 1: references in from the PC, and out from the first channel of
# each group: speeds (rad/s), voltages computed at that tick (V), references (rad/s); A, then B
IN_REFERENCE = {"a": 0, "b": 1}
OUT_SPEED, OUT_VOLTAGE, OUT_REFERENCE = 0, 2, 4


@dataclass(frozen=True)
class Firmware:
    """One of cartctl's firmwares: its name and the (channel key, label) of the channels it fills."""

    name: str
    labels: tuple[tuple[str, str], ...]


BRIDGE = Firmware(
    f"cartctl bridge version {BRIDGE_VERSION}",
    (
        (f"f{CH_SPEED_A}", "speed_a"),
        (f"f{CH_SPEED_B}", "speed_b"),
        (f"f{CH_APPLIED_A}", "voltage_a"),  # on the H-bridge at that tick (V)
        (f"f{CH_APPLIED_B}", "voltage_b"),
        (f"f{CH_POSITION_A}", "position_a_rad"),
        (f"f{CH_POSITION_B}", "position_b_rad"),
        (f"f{CH_BRIDGE_VERSION}", "bridge_version"),
        (f"i{CH_ECHO}", "echo_seq"),
        (f"i{CH_TICK}", "cart_tick"),
        (f"i{CH_STATUS}", "status"),
        (f"i{CH_HOST_LOST}", "host_frames_lost"),
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
"""A controller of ``cartctl export --arduino`` on the cart (channel layout :data:`ONBOARD_LAYOUT`)."""


def recognise_firmware(floats: Sequence[float], ints: Sequence[int]) -> Firmware | None:
    """Which of cartctl's firmwares sent a GPIO with these channels, or None for another one.

    :data:`BRIDGE` when float :data:`CH_FIRMWARE_ID` is the bridge's version, :data:`ONBOARD`
    when it is :data:`ONBOARD_ID`. Raises ValueError unless there are 8 floats and 4 ints.
    """
    check_gpio_counts(floats, ints)
    marker = floats[CH_FIRMWARE_ID]
    return {float(BRIDGE_VERSION): BRIDGE, float(ONBOARD_ID): ONBOARD}.get(marker)
