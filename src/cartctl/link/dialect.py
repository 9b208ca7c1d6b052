"""The microOS MAVLink dialect: message ids, CRC_EXTRA values and frame encoding.

The dialect is ``microos.xml`` next to this module. pymavlink's generator (mavgen) has turned it
into the Python module :mod:`cartctl.link.vendor.microos_mavlink`, which cartctl ships and imports:
its message classes pack and unpack the payloads and carry each message's CRC_EXTRA and payload
length. It is regenerated with ``tools/regenerate_dialect.py`` whenever the XML changes (a test
fails until it is). It was generated for wire protocol 2.0, so it writes both generations:

- "generation A" firmware speaks MAVLink 1 (start byte 0xFE): HEARTBEAT, THREAD_INFO, GPIO, EVENT
  and PRINT. The :class:`Encoder` packs them with ``force_mavlink1=True``. THREAD_INFO (id 1) is not
  in the XML because its fields are not known; only its length and CRC_EXTRA are, as constants.
- "generation B" firmware speaks MAVLink 2 (start byte 0xFD) and sends GPIOX (id 14) instead of
  GPIO. :func:`encode_gpiox_v2` packs one (pymavlink's MAVLink 2 framing, trailing zero bytes of
  the payload truncated), so that a virtual cart can impersonate a generation-B cart.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence

from cartctl.link.vendor import microos_mavlink as mavlink

__all__ = [
    "CRC_EXTRA",
    "GPIOX_CRC_EXTRA",
    "GPIOX_FLOAT_COUNT",
    "GPIOX_PAYLOAD_LENGTH",
    "GPIO_FLOAT_COUNT",
    "GPIO_INT_COUNT",
    "MAV_TYPE_CAR",
    "MSG_EVENT",
    "MSG_GPIO",
    "MSG_GPIOX",
    "MSG_HEARTBEAT",
    "MSG_PRINT",
    "MSG_THREAD_INFO",
    "PAYLOAD_LENGTH",
    "PRINT_TEXT_BYTES",
    "STX_V1",
    "STX_V2",
    "Encoder",
    "encode_gpiox_v2",
]

MSG_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
MSG_THREAD_INFO = 1
MSG_GPIO = mavlink.MAVLINK_MSG_ID_GPIO
MSG_EVENT = mavlink.MAVLINK_MSG_ID_EVENT
MSG_PRINT = mavlink.MAVLINK_MSG_ID_PRINT
MSG_GPIOX = mavlink.MAVLINK_MSG_ID_GPIOX
"""Message ids (0, 1, 3, 4, 5 and 14); GPIOX is generation B (MAVLink 2) only."""

STX_V1 = mavlink.PROTOCOL_MARKER_V1
"""Start byte of a MAVLink 1 frame (generation A), 0xFE."""
STX_V2 = mavlink.PROTOCOL_MARKER_V2
"""Start byte of a MAVLink 2 frame (generation B), 0xFD."""

MAV_TYPE_CAR = 20
"""HEARTBEAT ``type`` sent by the cart."""

GPIO_FLOAT_COUNT = 8
GPIO_INT_COUNT = 4
GPIOX_FLOAT_COUNT = 12
PRINT_TEXT_BYTES = 32
"""Capacity of one PRINT frame's text field, in bytes."""

_THREAD_INFO_PAYLOAD_LENGTH = 22
_THREAD_INFO_CRC_EXTRA = 215
_MAVLINK_VERSION = 2
_SEQ_MODULO = 256
_UINT8_MAX = 0xFF
_UINT32_MAX = 0xFFFF_FFFF


def _generation_a(
    value: Callable[[type[mavlink.MAVLink_message]], int], thread_info: int
) -> dict[int, int]:
    """``value`` of each generation-A message class, by id, with THREAD_INFO's ``thread_info``."""
    table = {i: value(cls) for i, cls in mavlink.mavlink_map.items() if i != MSG_GPIOX}
    table[MSG_THREAD_INFO] = thread_info
    return dict(sorted(table.items()))


CRC_EXTRA: dict[int, int] = _generation_a(lambda cls: cls.crc_extra, _THREAD_INFO_CRC_EXTRA)
"""CRC_EXTRA of each generation-A (MAVLink 1) message, by id."""
PAYLOAD_LENGTH: dict[int, int] = _generation_a(
    lambda cls: cls.unpacker.size, _THREAD_INFO_PAYLOAD_LENGTH
)
"""Payload length (bytes) of each generation-A (MAVLink 1) message, by id."""
GPIOX_CRC_EXTRA = mavlink.MAVLink_gpiox_message.crc_extra
"""CRC_EXTRA of GPIOX (221)."""
GPIOX_PAYLOAD_LENGTH = mavlink.MAVLink_gpiox_message.unpacker.size
"""GPIOX's full payload (52 bytes); a MAVLink 2 frame truncates its trailing zero bytes."""


def _check_range(name: str, value: int, maximum: int) -> None:
    if not 0 <= value <= maximum:
        raise ValueError(f"{name} must be in 0..{maximum}, got {value}")


def _pack(message: mavlink.MAVLink_message, mav: mavlink.MAVLink, error: str, v1: bool) -> bytes:
    """``message`` as a frame with ``mav``'s header fields, MAVLink 1 if ``v1`` else MAVLink 2.

    A field value that does not fit its wire type raises ValueError, ``error`` in front.
    """
    try:
        return message.pack(mav, force_mavlink1=v1)
    except (struct.error, OverflowError) as exc:
        raise ValueError(f"{error}: {exc}") from exc


def _utf8_chunks(text: str, size: int) -> list[bytes]:
    """Split the UTF-8 bytes of ``text`` into chunks of at most ``size`` bytes, on char bounds."""
    raw = text.encode("utf-8")
    chunks: list[bytes] = []
    start = 0
    while start < len(raw):
        end = min(start + size, len(raw))
        # Do not cut a multi-byte character: back up over continuation bytes (10xxxxxx).
        while end < len(raw) and end > start + 1 and (raw[end] & 0xC0) == 0x80:
            end -= 1
        chunks.append(raw[start:end])
        start = end
    return chunks


class Encoder:
    """Encodes generation-A (MAVLink 1) frames with a running sequence number.

    Parameters
    ----------
    sysid, compid
        Source system and component written into every frame (QRC and the cart use 0, 0).

    Attributes
    ----------
    seq : int
        Sequence number of the next frame, 0..255; every frame consumes one and it wraps.
    """

    def __init__(self, sysid: int = 0, compid: int = 0) -> None:
        self.sysid = sysid
        self.compid = compid
        self.seq = 0
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def _pack(self, message: mavlink.MAVLink_message, error: str) -> bytes:
        self._mav.seq = self.seq
        frame = _pack(message, self._mav, error, v1=True)
        self.seq = (self.seq + 1) % _SEQ_MODULO
        return frame

    def gpio(self, time_ms: int, floats: Sequence[float], ints: Sequence[int]) -> bytes:
        """One GPIO frame.

        Parameters
        ----------
        time_ms
            Sender time in ms (uint32).
        floats
            The 8 float channels (sent as float32).
        ints
            The 4 int channels (int32).

        Returns
        -------
        bytes
            The 60-byte frame.

        Raises
        ------
        ValueError
            On a wrong number of channels or a value that does not fit its wire type.
        """
        if len(floats) != GPIO_FLOAT_COUNT or len(ints) != GPIO_INT_COUNT:
            raise ValueError(
                f"GPIO needs {GPIO_FLOAT_COUNT} floats and {GPIO_INT_COUNT} ints, "
                f"got {len(floats)} and {len(ints)}"
            )
        _check_range("time_ms", time_ms, _UINT32_MAX)
        message = mavlink.MAVLink_gpio_message(
            time_ms, [float(x) for x in floats], [int(i) for i in ints]
        )
        return self._pack(message, "GPIO channel value does not fit its wire type")

    def thread_info(
        self,
        time_ms: int,
        thread_id: int,
        duration_us: int,
        *,
        latency_us: int = 0,
        total_duration_us: int = 0,
        total_latency_us: int = 0,
        executions: int = 0,
        priority: int = 0,
    ) -> bytes:
        """One THREAD_INFO frame (30 bytes): a firmware thread's timing, as microOS packs it.

        The payload, in wire order (fields sorted by size): time, total duration, total latency
        and executions (uint32), the last duration and latency (µs, uint16), the thread's id and
        priority (uint8).
        """
        values = (time_ms, total_duration_us, total_latency_us, executions, duration_us,
                  latency_us, thread_id, priority)  # fmt: skip
        try:
            payload = struct.pack("<IIIIHHBB", *values)
        except struct.error as exc:
            raise ValueError(f"THREAD_INFO field does not fit its wire type: {exc}") from exc
        header = bytes((STX_V1, len(payload), self.seq, self.sysid, self.compid, MSG_THREAD_INFO))
        crc = mavlink.x25crc(header[1:] + payload + bytes((_THREAD_INFO_CRC_EXTRA,))).crc
        self.seq = (self.seq + 1) % _SEQ_MODULO
        return header + payload + struct.pack("<H", crc)

    def heartbeat(self, time_ms: int, type: int = MAV_TYPE_CAR, data: bytes = bytes(8)) -> bytes:
        """One HEARTBEAT frame (``mavlink_version`` 2).

        Parameters
        ----------
        time_ms
            Sender time in ms (uint32).
        type
            Vehicle type, 20 (car) by default.
        data
            The 8 data bytes (unused by microOS).

        Returns
        -------
        bytes
            The 22-byte frame.
        """
        if len(data) != 8:
            raise ValueError(f"HEARTBEAT data must be 8 bytes, got {len(data)}")
        _check_range("time_ms", time_ms, _UINT32_MAX)
        message = mavlink.MAVLink_heartbeat_message(time_ms, type, list(data), _MAVLINK_VERSION)
        return self._pack(message, "HEARTBEAT field out of range")

    def event(self, type: int) -> bytes:
        """One EVENT frame (``type`` 1000..1007 are QRC's buttons 0..7)."""
        _check_range("EVENT type", type, 0xFFFF)
        return self._pack(mavlink.MAVLink_event_message(type), "EVENT type out of range")

    def print_text(self, text: str) -> list[bytes]:
        """PRINT frames carrying ``text`` (UTF-8), split into chunks of at most 32 bytes.

        A multi-byte character is never split over two frames. An empty text gives no frame.

        Raises
        ------
        ValueError
            If ``text`` contains a NUL character (the receiver would cut the text there).
        """
        if "\x00" in text:
            raise ValueError("PRINT text must not contain NUL characters")
        return [
            self._pack(mavlink.MAVLink_print_message(chunk), "PRINT text does not fit")
            for chunk in _utf8_chunks(text, PRINT_TEXT_BYTES)
        ]


def encode_gpiox_v2(
    time_ms: int,
    floats: Sequence[float],
    *,
    seq: int = 0,
    sysid: int = 0,
    compid: int = 0,
) -> bytes:
    """A generation-B GPIOX frame (MAVLink 2, id 14): time and 12 float channels.

    pymavlink's MAVLink 2 framing truncates trailing zero bytes of the 52-byte payload (at least
    one byte stays). The frame is unsigned (incompat flags 0).

    Parameters
    ----------
    time_ms
        Sender time in ms (uint32).
    floats
        The 12 float channels (sent as float32).
    seq, sysid, compid
        Header fields, 0..255 each.

    Returns
    -------
    bytes
        The frame, 13 to 64 bytes long.

    Raises
    ------
    ValueError
        On a wrong number of channels or a value that does not fit its wire type.
    """
    if len(floats) != GPIOX_FLOAT_COUNT:
        raise ValueError(f"GPIOX needs {GPIOX_FLOAT_COUNT} floats, got {len(floats)}")
    _check_range("time_ms", time_ms, _UINT32_MAX)
    for name, value in (("seq", seq), ("sysid", sysid), ("compid", compid)):
        _check_range(name, value, _UINT8_MAX)
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.seq = seq
    message = mavlink.MAVLink_gpiox_message(time_ms, floats)
    return _pack(message, mav, "GPIOX channel value does not fit float32", v1=False)
