"""The cart's serial link and its emulation (the wire protocol: docs/serial-protocol.md).

Pure, no I/O: :mod:`~cartctl.link.dialect` (ids, CRC_EXTRA, the :class:`Encoder`, on the generated
:mod:`~cartctl.link.vendor.microos_mavlink`), :mod:`~cartctl.link.framer` (messages,
:class:`Framer`, :class:`LineAssembler`), :mod:`~cartctl.link.bridge` (the bridge sketch's channel
map), :mod:`~cartctl.link.firmware` (which firmware, and the firmwares' logic) and
:mod:`~cartctl.link.loop_delay`. The host's side of the port: :mod:`~cartctl.link.cart_link`,
:mod:`~cartctl.link.serial_cart` (the PC-side loop's plant) and :mod:`~cartctl.link.cart_monitor`.
The cart, emulated: :mod:`~cartctl.link.cart_uart` (its serial port) and
:mod:`~cartctl.link.virtual_cart`, with its options in :mod:`~cartctl.link.cart_faults`. The
framing's names are re-exported here.
"""

from cartctl.link.bridge import SEQ_MODULO, CartSample, HostCommand, next_seq, tick_difference
from cartctl.link.dialect import (
    CRC_EXTRA,
    GPIOX_CRC_EXTRA,
    PAYLOAD_LENGTH,
    Encoder,
    encode_gpiox_v2,
)
from cartctl.link.framer import (
    Event,
    Framer,
    GenerationBFrame,
    Gpio,
    Heartbeat,
    LineAssembler,
    LinkStats,
    Message,
    PrintText,
    ThreadInfo,
)

__all__ = [
    "CRC_EXTRA",
    "GPIOX_CRC_EXTRA",
    "PAYLOAD_LENGTH",
    "SEQ_MODULO",
    "CartSample",
    "Encoder",
    "Event",
    "Framer",
    "GenerationBFrame",
    "Gpio",
    "Heartbeat",
    "HostCommand",
    "LineAssembler",
    "LinkStats",
    "Message",
    "PrintText",
    "ThreadInfo",
    "encode_gpiox_v2",
    "next_seq",
    "tick_difference",
]
