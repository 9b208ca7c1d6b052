"""Which of cartctl's firmwares a cart runs, told by what it sends, and what its channels carry.

Float channel 6 (:data:`CH_FIRMWARE_ID`) of every GPIO that cartctl's firmware sends says which
one it is:

- 1..999: the bridge sketch (``firmware/cartctl_bridge``) of that version; its channel map
  (:mod:`cartctl.link.bridge`) is known for version :data:`~cartctl.link.bridge.BRIDGE_VERSION`;
- ``1000 + n``: a controller of ``cartctl export --arduino`` running on the cart, channel layout n
  (:data:`ONBOARD_ID`, layout :data:`ONBOARD_LAYOUT` today): floats 0/1 speed A/B (rad/s), 2/3
  voltage A/B computed at that tick (V), 4/5 reference A/B (rad/s), in from the PC floats 0/1 the
  references;
- anything else (0 from the course's own code or a bridge before version 2): not cartctl's.

:func:`recognise_firmware` reads one frame's channels and returns the :class:`Firmware` with the
labels of its channels, named as the columns of a trace (``speed_a``, ``voltage_a``,
``reference_a``: docs/architecture.md's trace columns), so that ``review``, ``validate`` and
``convert`` read a ``cartctl monitor`` trace of it as it is. Pure: no I/O.
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
from cartctl.link.dialect import GPIO_FLOAT_COUNT, GPIO_INT_COUNT

__all__ = [
    "BRIDGE",
    "CHANNEL_KEYS",
    "CH_FIRMWARE_ID",
    "IN_REFERENCE",
    "ONBOARD",
    "ONBOARD_ID",
    "ONBOARD_LAYOUT",
    "OUT_REFERENCE",
    "OUT_SPEED",
    "OUT_VOLTAGE",
    "Firmware",
    "recognise_firmware",
]

CHANNEL_KEYS: tuple[str, ...] = (
    *(f"f{i}" for i in range(GPIO_FLOAT_COUNT)),
    *(f"i{i}" for i in range(GPIO_INT_COUNT)),
)
"""A GPIO's channels in frame order: float channels f0..f7, then int channels i0..i3."""
CH_FIRMWARE_ID = CH_BRIDGE_VERSION
"""The float channel in which cartctl's firmware says which it is (the bridge's version)."""
ONBOARD_LAYOUT = 1
"""The channel layout of the on-board export (below)."""
ONBOARD_ID = 1000 + ONBOARD_LAYOUT
"""What the on-board export sends in float :data:`CH_FIRMWARE_ID`: 1000 + its layout."""
# the on-board export's layout 1
IN_REFERENCE = {"a": 0, "b": 1}
"""Input float channel of each motor's reference (rad/s), from the PC."""
OUT_SPEED, OUT_VOLTAGE, OUT_REFERENCE = 0, 2, 4
"""First output float channel of the speeds, voltages and references (motor A, then B)."""


@dataclass(frozen=True)
class Firmware:
    """One of cartctl's firmwares, as recognised from a frame.

    Attributes
    ----------
    name : str
        What it is, e.g. ``"cartctl bridge version 2"``.
    labels : tuple of (str, str)
        (channel key, label) of the channels it fills, keys as in :data:`CHANNEL_KEYS`; the
        others are not named.
    """

    name: str
    labels: tuple[tuple[str, str], ...]

    def label_of(self) -> dict[str, str]:
        """Channel key → label, for the channels it names."""
        return dict(self.labels)


def _float(channel: int) -> str:
    return f"f{channel}"


def _int(channel: int) -> str:
    return f"i{channel}"


BRIDGE = Firmware(
    f"cartctl bridge version {BRIDGE_VERSION}",
    (
        (_float(CH_SPEED_A), "speed_a"),
        (_float(CH_SPEED_B), "speed_b"),
        (_float(CH_APPLIED_A), "voltage_a"),  # on the H-bridge at that tick (V)
        (_float(CH_APPLIED_B), "voltage_b"),
        (_float(CH_POSITION_A), "position_a_rad"),
        (_float(CH_POSITION_B), "position_b_rad"),
        (_float(CH_BRIDGE_VERSION), "bridge_version"),
        (_int(CH_ECHO), "echo_seq"),
        (_int(CH_TICK), "cart_tick"),
        (_int(CH_STATUS), "status"),
        (_int(CH_HOST_LOST), "host_frames_lost"),
    ),
)
"""The bridge sketch of version :data:`~cartctl.link.bridge.BRIDGE_VERSION`."""
ONBOARD = Firmware(
    f"cartctl on-board controller ('cartctl export --arduino', layout {ONBOARD_LAYOUT})",
    (
        *((_float(OUT_SPEED + i), f"speed_{m}") for i, m in enumerate(IN_REFERENCE)),
        *((_float(OUT_VOLTAGE + i), f"voltage_{m}") for i, m in enumerate(IN_REFERENCE)),
        *((_float(OUT_REFERENCE + i), f"reference_{m}") for i, m in enumerate(IN_REFERENCE)),
        (_float(CH_FIRMWARE_ID), "firmware_id"),
    ),
)
"""A controller of ``cartctl export --arduino`` on the cart (channel layout :data:`ONBOARD_LAYOUT`)."""


def recognise_firmware(floats: Sequence[float], ints: Sequence[int]) -> Firmware | None:
    """Which of cartctl's firmwares sent a GPIO with these channels, or None for another one.

    Parameters
    ----------
    floats : sequence of float
        The frame's 8 float channels.
    ints : sequence of int
        Its 4 int channels (not needed for the marker today; checked for their count).

    Returns
    -------
    Firmware or None
        :data:`BRIDGE` when float :data:`CH_FIRMWARE_ID` is the bridge's version,
        :data:`ONBOARD` when it is :data:`ONBOARD_ID`, else None.

    Raises
    ------
    ValueError
        Not 8 floats and 4 ints.
    """
    if len(floats) != GPIO_FLOAT_COUNT or len(ints) != GPIO_INT_COUNT:
        raise ValueError(
            f"GPIO has {GPIO_FLOAT_COUNT} floats and {GPIO_INT_COUNT} ints, "
            f"got {len(floats)} and {len(ints)}"
        )
    marker = floats[CH_FIRMWARE_ID]
    if marker == float(BRIDGE_VERSION):
        return BRIDGE
    if marker == float(ONBOARD_ID):
        return ONBOARD
    return None
