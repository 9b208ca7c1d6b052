"""The cart's serial link, without I/O: microOS MAVLink framing and the bridge channel map.

- :mod:`~cartctl.link.dialect`: message ids, CRC_EXTRA, the pymavlink-generated dialect module and
  the :class:`Encoder` of generation-A frames (plus :func:`encode_gpiox_v2` for generation B);
- :mod:`~cartctl.link.messages`: the decoded messages;
- :mod:`~cartctl.link.framer`: :class:`Framer`, bytes in, messages out, with :class:`LinkStats`;
- :mod:`~cartctl.link.text`: :class:`LineAssembler`, PRINT fragments to lines;
- :mod:`~cartctl.link.bridge`: the GPIO channel map of the bridge sketch, both directions.

See docs/serial-protocol.md for the wire protocol.
"""

from cartctl.link.bridge import (
    CH_APPLIED_A,
    CH_APPLIED_B,
    CH_DRIVE,
    CH_ECHO,
    CH_HOST_LOST,
    CH_POSITION_A,
    CH_POSITION_B,
    CH_SEQ,
    CH_SPEED_A,
    CH_SPEED_B,
    CH_STATUS,
    CH_TICK,
    CH_VOLTAGE_A,
    CH_VOLTAGE_B,
    SEQ_MODULO,
    STATUS_DRIVING,
    STATUS_WATCHDOG,
    WATCHDOG_MS,
    CartSample,
    HostCommand,
    next_seq,
    tick_difference,
)
from cartctl.link.dialect import (
    CRC_EXTRA,
    GPIOX_CRC_EXTRA,
    MAV_TYPE_CAR,
    MSG_EVENT,
    MSG_GPIO,
    MSG_GPIOX,
    MSG_HEARTBEAT,
    MSG_PRINT,
    MSG_THREAD_INFO,
    PAYLOAD_LENGTH,
    STX_V1,
    STX_V2,
    Encoder,
    encode_gpiox_v2,
    generated_module,
)
from cartctl.link.framer import Framer, LinkStats
from cartctl.link.messages import (
    Event,
    GenerationBFrame,
    Gpio,
    Heartbeat,
    Message,
    PrintText,
    ThreadInfo,
)
from cartctl.link.text import LineAssembler

__all__ = [
    "CH_APPLIED_A",
    "CH_APPLIED_B",
    "CH_DRIVE",
    "CH_ECHO",
    "CH_HOST_LOST",
    "CH_POSITION_A",
    "CH_POSITION_B",
    "CH_SEQ",
    "CH_SPEED_A",
    "CH_SPEED_B",
    "CH_STATUS",
    "CH_TICK",
    "CH_VOLTAGE_A",
    "CH_VOLTAGE_B",
    "CRC_EXTRA",
    "GPIOX_CRC_EXTRA",
    "MAV_TYPE_CAR",
    "MSG_EVENT",
    "MSG_GPIO",
    "MSG_GPIOX",
    "MSG_HEARTBEAT",
    "MSG_PRINT",
    "MSG_THREAD_INFO",
    "PAYLOAD_LENGTH",
    "SEQ_MODULO",
    "STATUS_DRIVING",
    "STATUS_WATCHDOG",
    "STX_V1",
    "STX_V2",
    "WATCHDOG_MS",
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
    "generated_module",
    "next_seq",
    "tick_difference",
]
