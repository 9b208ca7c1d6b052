"""The microOS MAVLink dialect: message ids, CRC_EXTRA values and frame encoding.

``microos.xml`` beside this module is made into :mod:`cartctl.link.vendor.microos_mavlink` by
pymavlink's mavgen (``tools/regenerate_dialect.py``). Generation-A firmware speaks MAVLink 1 (0xFE;
:class:`Encoder`); THREAD_INFO (id 1) is not in the XML, only its length and CRC_EXTRA are known.
Generation B speaks MAVLink 2 (0xFD) with GPIOX (id 14): :func:`encode_gpiox_v2` lets a virtual
cart impersonate one.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from cartctl.link.vendor import microos_mavlink as mavlink

MSG_HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
MSG_THREAD_INFO = 1
MSG_GPIO = mavlink.MAVLINK_MSG_ID_GPIO
MSG_EVENT = mavlink.MAVLINK_MSG_ID_EVENT
MSG_PRINT = mavlink.MAVLINK_MSG_ID_PRINT
MSG_GPIOX = mavlink.MAVLINK_MSG_ID_GPIOX
STX_V1 = mavlink.PROTOCOL_MARKER_V1  # 0xFE

GPIO_FLOAT_COUNT = 8
GPIO_INT_COUNT = 4
_THREAD_INFO_PAYLOAD_LENGTH = 22
_THREAD_INFO_CRC_EXTRA = 215
_UINT32_MAX = 0xFFFF_FFFF
_GENERATION_A = {i: cls for i, cls in sorted(mavlink.mavlink_map.items()) if i != MSG_GPIOX}

CRC_EXTRA: dict[int, int] = {i: cls.crc_extra for i, cls in _GENERATION_A.items()}
"""CRC_EXTRA of each generation-A (MAVLink 1) message, by id."""
PAYLOAD_LENGTH: dict[int, int] = {i: cls.unpacker.size for i, cls in _GENERATION_A.items()}
"""Payload length (bytes) of each generation-A (MAVLink 1) message, by id."""
CRC_EXTRA[MSG_THREAD_INFO] = _THREAD_INFO_CRC_EXTRA
PAYLOAD_LENGTH[MSG_THREAD_INFO] = _THREAD_INFO_PAYLOAD_LENGTH
GPIOX_CRC_EXTRA = mavlink.MAVLink_gpiox_message.crc_extra
GPIOX_PAYLOAD_LENGTH = mavlink.MAVLink_gpiox_message.unpacker.size
"""52 bytes; a MAVLink 2 frame truncates its trailing zero bytes."""


def check_gpio_counts(floats: Sequence[float], ints: Sequence[int]) -> None:
    """Raise ValueError unless there are 8 float and 4 int channels."""
    if len(floats) != GPIO_FLOAT_COUNT or len(ints) != GPIO_INT_COUNT:
        raise ValueError(
            f"GPIO needs {GPIO_FLOAT_COUNT} floats and {GPIO_INT_COUNT} ints, "
            f"got {len(floats)} and {len(ints)}"
        )


def _check_range(name: str, value: int, maximum: int) -> None:
    if not 0 <= value <= maximum:
        raise ValueError(f"{name} must be in 0..{maximum}, got {value}")


def _pack(message: mavlink.MAVLink_message, mav: mavlink.MAVLink, error: str, v1: bool) -> bytes:
    """``message`` framed with ``mav``'s header; a value that does not fit raises ValueError."""
    try:
        return message.pack(mav, force_mavlink1=v1)
    except (struct.error, OverflowError) as exc:
        raise ValueError(f"{error}: {exc}") from exc


def _utf8_chunks(text: str, size: int) -> list[bytes]:
    """The UTF-8 bytes of ``text`` in chunks of at most ``size`` bytes, cut on character bounds."""
    raw = text.encode("utf-8")
    chunks: list[bytes] = []
    start = 0
    while start < len(raw):
        end = min(start + size, len(raw))
        while end < len(raw) and end > start + 1 and (raw[end] & 0xC0) == 0x80:
            end -= 1  # back up over continuation bytes (10xxxxxx)
        chunks.append(raw[start:end])
        start = end
    return chunks


class Encoder:
    """Encodes generation-A (MAVLink 1) frames from ``sysid``, ``compid`` (QRC and the cart use
    0, 0); :attr:`seq` is the next frame's sequence number, 0..255, +1 per frame."""

    def __init__(self, sysid: int = 0, compid: int = 0) -> None:
        self.sysid = sysid
        self.compid = compid
        self.seq = 0
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def _pack(self, message: mavlink.MAVLink_message, error: str) -> bytes:
        self._mav.seq = self.seq
        frame = _pack(message, self._mav, error, v1=True)
        self.seq = (self.seq + 1) % 256
        return frame

    def gpio(self, time_ms: int, floats: Sequence[float], ints: Sequence[int]) -> bytes:
        """One 60-byte GPIO frame: time (ms, uint32), 8 float32 and 4 int32 channels.

        Raises ValueError on a wrong number of channels or a value that does not fit its type.
        """
        check_gpio_counts(floats, ints)
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
        self.seq = (self.seq + 1) % 256
        return header + payload + struct.pack("<H", crc)

    def heartbeat(self, time_ms: int, type: int = 20, data: bytes = bytes(8)) -> bytes:
        """One 22-byte HEARTBEAT frame (``type`` 20 is a car; ``data``: 8 bytes microOS ignores)."""
        if len(data) != 8:
            raise ValueError(f"HEARTBEAT data must be 8 bytes, got {len(data)}")
        _check_range("time_ms", time_ms, _UINT32_MAX)
        message = mavlink.MAVLink_heartbeat_message(time_ms, type, list(data), 2)
        return self._pack(message, "HEARTBEAT field out of range")

    def event(self, type: int) -> bytes:
        """One EVENT frame (``type`` 1000..1007 are QRC's buttons 0..7)."""
        _check_range("EVENT type", type, 0xFFFF)
        return self._pack(mavlink.MAVLink_event_message(type), "EVENT type out of range")

    def print_text(self, text: str) -> list[bytes]:
        """PRINT frames carrying ``text`` (UTF-8) in chunks of at most 32 bytes.

        A multi-byte character is never split over two frames; an empty text gives no frame. A NUL
        character raises ValueError (the receiver would cut the text there).
        """
        if "\x00" in text:
            raise ValueError("PRINT text must not contain NUL characters")
        return [
            self._pack(mavlink.MAVLink_print_message(chunk), "PRINT text does not fit")
            for chunk in _utf8_chunks(text, 32)
        ]


def encode_gpiox_v2(
    time_ms: int, floats: Sequence[float], *, seq: int = 0, sysid: int = 0, compid: int = 0
) -> bytes:
    """A generation-B GPIOX frame (MAVLink 2, id 14, unsigned): time (ms) and 12 float channels.

    pymavlink's MAVLink 2 framing truncates trailing zero bytes of the 52-byte payload (at least
    one byte stays), so the frame is 13 to 64 bytes long. Raises ValueError on a wrong number of
    channels or a value that does not fit its wire type (header fields 0..255).
    """
    if len(floats) != 12:
        raise ValueError(f"GPIOX needs 12 floats, got {len(floats)}")
    _check_range("time_ms", time_ms, _UINT32_MAX)
    for name, value in (("seq", seq), ("sysid", sysid), ("compid", compid)):
        _check_range(name, value, 0xFF)
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.seq = seq
    message = mavlink.MAVLink_gpiox_message(time_ms, floats)
    return _pack(message, mav, "GPIOX channel value does not fit float32", v1=False)
