"""The cart's serial link and its emulation (docs/architecture.md maps the modules).

The pure framing (dialect, the bridge's channel map) imports nothing of cartctl's; its names are
re-exported here. The wire protocol is docs/serial-protocol.md.
"""

from cartctl.link.bridge import SEQ_MODULO, CartSample, HostCommand, next_seq, tick_difference
from cartctl.link.dialect import (
    CRC_EXTRA,
    GPIOX_CRC_EXTRA,
    PAYLOAD_LENGTH,
    Encoder,
    Event,
    Framer,
    GenerationBFrame,
    Gpio,
    Heartbeat,
    LineAssembler,
    Message,
    PrintText,
    ThreadInfo,
    encode_gpiox_v2,
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
    "Message",
    "PrintText",
    "ThreadInfo",
    "encode_gpiox_v2",
    "next_seq",
    "tick_difference",
]
