"""The microOS MAVLink dialect: encoding frames, and :class:`Framer` decoding them (pure, no I/O).

``microos.xml`` beside this module is made into :mod:`cartctl.link.vendor.microos_mavlink` by
pymavlink's mavgen (``tools/regenerate_dialect.py``), which packs and unpacks the payloads.
Generation A speaks MAVLink 1 (0xFE), generation B MAVLink 2 (0xFD) with GPIOX (id 14). On a
header that fits no known message, or a CRC mismatch, :class:`Framer` drops only the start byte,
so a false start in line noise never swallows the real frame that follows (pymavlink's parser
can). Every message carries the frame's ``seq``, ``sysid`` and ``compid`` last, with defaults.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any, TypeAlias

from cartctl.link.vendor import microos_mavlink as mavlink

MSG_THREAD_INFO = 1
MSG_GPIOX = mavlink.MAVLINK_MSG_ID_GPIOX
STX_V1 = mavlink.PROTOCOL_MARKER_V1  # 0xFE

GPIO_FLOAT_COUNT = 8
GPIO_INT_COUNT = 4
_UINT32_MAX = 0xFFFF_FFFF


class _ThreadInfoMessage(mavlink.MAVLink_message):
    """THREAD_INFO (id 1), not in the XML. Its 22-byte payload in wire order (fields sorted by
    size): time, total duration, total latency and executions (uint32), the last duration and
    latency (µs, uint16), the thread's id and priority (uint8)."""

    crc_extra = 215
    unpacker = struct.Struct("<IIIIHHBB")

    def __init__(self, *values: int) -> None:
        super().__init__(MSG_THREAD_INFO, "THREAD_INFO")
        self.values = values

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(*self.values)
        return self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)


_GENERATION_A: dict[int, type[mavlink.MAVLink_message]] = {
    i: cls
    for i, cls in sorted({**mavlink.mavlink_map, MSG_THREAD_INFO: _ThreadInfoMessage}.items())
    if i != MSG_GPIOX
}

CRC_EXTRA: dict[int, int] = {i: cls.crc_extra for i, cls in _GENERATION_A.items()}
"""CRC_EXTRA of each generation-A (MAVLink 1) message, by id."""
PAYLOAD_LENGTH: dict[int, int] = {i: cls.unpacker.size for i, cls in _GENERATION_A.items()}
"""Payload length (bytes) of each generation-A (MAVLink 1) message, by id."""
GPIOX_CRC_EXTRA = mavlink.MAVLink_gpiox_message.crc_extra
GPIOX_PAYLOAD_LENGTH = mavlink.MAVLink_gpiox_message.unpacker.size  # 52, less its trailing zeros


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


def _utf8_chunks(text: str, size: int) -> list[bytes]:
    """The UTF-8 bytes of ``text`` in chunks of at most ``size`` bytes, cut on character bounds."""
    chunks = [b""]
    for char in text:
        raw = char.encode("utf-8")
        if len(chunks[-1]) + len(raw) > size:
            chunks.append(b"")
        chunks[-1] += raw
    return [chunk for chunk in chunks if chunk]


class Encoder:
    """Encodes generation-A (MAVLink 1) frames from ``sysid``, ``compid`` (QRC and the cart: 0, 0);
    :attr:`seq` is the next frame's sequence number, 0..255, +1 per frame."""

    def __init__(self, sysid: int = 0, compid: int = 0) -> None:
        self.seq = 0
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def _pack(self, message: mavlink.MAVLink_message, error: str, v1: bool = True) -> bytes:
        """``message`` framed with :attr:`seq`; a value that does not fit: ValueError(``error``)."""
        self._mav.seq = self.seq
        try:
            frame = message.pack(self._mav, force_mavlink1=v1)
        except (struct.error, OverflowError) as exc:
            raise ValueError(f"{error}: {exc}") from exc
        self.seq = (self.seq + 1) % 256
        return frame

    def gpio(self, time_ms: int, floats: Sequence[float], ints: Sequence[int]) -> bytes:
        """One 60-byte GPIO frame: time (ms, uint32), 8 float32 and 4 int32 channels (ValueError
        on a wrong number of channels or a value that does not fit its type)."""
        check_gpio_counts(floats, ints)
        _check_range("time_ms", time_ms, _UINT32_MAX)
        message = mavlink.MAVLink_gpio_message(
            time_ms, [float(x) for x in floats], [int(i) for i in ints]
        )
        return self._pack(message, "GPIO channel value does not fit its wire type")

    def thread_info(
        self, time_ms: int, thread_id: int, duration_us: int, *, executions: int = 0
    ) -> bytes:
        """One THREAD_INFO frame (30 bytes) as the bridge sketch sends its timing reports through
        microOS's sendThreadInfo: a value in the duration field, the executions, and priority,
        latency and totals 0 (microOS's own thread reports fill those; nothing here sends one)."""
        message = _ThreadInfoMessage(time_ms, 0, 0, executions, duration_us, 0, thread_id, 0)
        return self._pack(message, "THREAD_INFO field does not fit its wire type")

    def heartbeat(self, time_ms: int, type: int = 20, data: bytes = bytes(8)) -> bytes:
        """One 22-byte HEARTBEAT frame (``type`` 20 is a car; ``data``: 8 bytes microOS ignores)."""
        if len(data) != 8:
            raise ValueError(f"HEARTBEAT data must be 8 bytes, got {len(data)}")
        message = mavlink.MAVLink_heartbeat_message(time_ms, type, list(data), 2)
        return self._pack(message, "HEARTBEAT field out of range")

    def event(self, type: int) -> bytes:
        """One EVENT frame (``type`` 1000..1007 are QRC's buttons 0..7)."""
        return self._pack(mavlink.MAVLink_event_message(type), "EVENT type out of range")

    def print_text(self, text: str) -> list[bytes]:
        """PRINT frames carrying ``text`` (UTF-8) in chunks of at most 32 bytes, never within a
        character; none for an empty text. A NUL raises ValueError (the receiver would cut there)."""
        if "\x00" in text:
            raise ValueError("PRINT text must not contain NUL characters")
        return [
            self._pack(mavlink.MAVLink_print_message(chunk), "PRINT text does not fit")
            for chunk in _utf8_chunks(text, 32)
        ]


def encode_gpiox_v2(
    time_ms: int, floats: Sequence[float], *, seq: int = 0, sysid: int = 0, compid: int = 0
) -> bytes:
    """A generation-B GPIOX frame (MAVLink 2, id 14, unsigned): time (ms) and 12 float channels,
    13 to 64 bytes (trailing zeros of the payload are cut). Raises ValueError on a wrong number of
    channels or a value that does not fit its wire type (header fields 0..255)."""
    if len(floats) != 12:
        raise ValueError(f"GPIOX needs 12 floats, got {len(floats)}")
    _check_range("time_ms", time_ms, _UINT32_MAX)
    for name, value in (("seq", seq), ("sysid", sysid), ("compid", compid)):
        _check_range(name, value, 0xFF)
    encoder = Encoder(sysid, compid)
    encoder.seq = seq
    message = mavlink.MAVLink_gpiox_message(time_ms, floats)
    return encoder._pack(message, "GPIOX channel value does not fit float32", v1=False)


BUTTON_EVENT_BASE = 1000  # EVENT type of QRC's button 0; buttons 0..7 are 1000..1007


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """HEARTBEAT (id 0): the cart's sign of life, every 1.1 s."""

    time_ms: int
    type: int
    data: bytes
    mavlink_version: int
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class Gpio:
    """GPIO (id 3): 8 float (float32) and 4 int (int32) channels, in either direction."""

    time_ms: int
    floats: tuple[float, ...]
    ints: tuple[int, ...]
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class Event:
    """EVENT (id 4), e.g. a QRC button press."""

    type: int
    seq: int = 0
    sysid: int = 0
    compid: int = 0

    @property
    def button(self) -> int | None:
        """The QRC button 0..7 this event stands for, or None for another event type."""
        index = self.type - BUTTON_EVENT_BASE
        return index if 0 <= index < 8 else None


@dataclass(frozen=True, slots=True)
class PrintText:
    """PRINT (id 5): up to 32 bytes of firmware text, NUL padding stripped (see LineAssembler)."""

    text: str
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class ThreadInfo:
    """THREAD_INFO (id 1): a firmware thread's timing report, its 22 bytes uninterpreted."""

    payload: bytes
    seq: int = 0
    sysid: int = 0
    compid: int = 0


@dataclass(frozen=True, slots=True)
class GenerationBFrame:
    """A valid MAVLink 2 frame of a generation-B cart (only GPIOX, id 14, is recognised)."""

    msgid: int
    seq: int = 0
    sysid: int = 0
    compid: int = 0


Message: TypeAlias = Heartbeat | Gpio | Event | PrintText | ThreadInfo | GenerationBFrame
"""Any decoded message; usable with ``isinstance``."""


class LineAssembler:
    """Joins PRINT texts (32-byte pieces, cut anywhere) into lines: a line ends at "\\n"; every
    "\\r" is dropped, so a "\\r\\n" split over two frames still ends exactly one line."""

    def __init__(self) -> None:
        self._partial: list[str] = []  # pieces, joined once the line ends: no copy per fragment

    def feed(self, text: str) -> list[str]:
        """Add a fragment; return the lines it completes (oldest first, without line endings)."""
        *lines, last = text.replace("\r", "").split("\n")
        if lines:
            lines[0] = "".join([*self._partial, lines[0]])
            self._partial = []
        if last:
            self._partial.append(last)
        return lines

    def flush(self) -> str | None:
        """Return and clear the unfinished line, or None if there is none."""
        partial = "".join(self._partial)
        self._partial = []
        return partial or None


_START = re.compile(rb"[\xfd\xfe]")
_V1_HEADER = mavlink.HEADER_LEN_V1
_V2_HEADER = mavlink.HEADER_LEN_V2
_V2_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_WAIT, _REJECT = 0, -1  # a frame check's verdict besides a size: wait for bytes, or not a frame


@dataclass
class LinkStats:
    """Counters of a link's receive side."""

    frames: int = 0  # valid frames decoded (both generations)
    crc_errors: int = 0  # generation-A frames with a plausible header but a wrong checksum
    garbage_bytes: int = 0  # bytes that belong to no valid frame, each counted once
    seq_gaps: int = 0  # times a source's (sysid, compid) sequence number did not advance by one
    lost_frames: int = 0  # frames missing according to those gaps
    generation_b_frames: int = 0  # valid MAVLink 2 GPIOX frames (a generation-B cart)

    def to_dict(self) -> dict[str, int]:
        return asdict(self)


def _crc_ok(buf: bytearray, start: int, crc_at: int, extra: int) -> bool:
    """Whether the CRC at ``buf[crc_at:crc_at + 2]`` matches ``buf[start:crc_at]`` + ``extra``."""
    crc = mavlink.x25crc(bytes(buf[start:crc_at]) + bytes((extra,))).crc
    return crc == buf[crc_at] | (buf[crc_at + 1] << 8)


def _convert(msgid: int, frame: bytes, mav: mavlink.MAVLink, *header: int) -> Message:
    """The message of a checked generation-A frame; pymavlink's module unpacks the payload."""
    if msgid == MSG_THREAD_INFO:
        return ThreadInfo(frame[_V1_HEADER:-2], *header)
    m: Any = mav.decode(bytearray(frame))
    if msgid == mavlink.MAVLINK_MSG_ID_GPIO:
        return Gpio(m.time, tuple(m.gpio_float), tuple(m.gpio_int), *header)
    if msgid == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
        return Heartbeat(m.time, m.type, bytes(m.data), m.mavlink_version, *header)
    if msgid == mavlink.MAVLINK_MSG_ID_EVENT:
        return Event(m.type, *header)
    return PrintText(m.text, *header)  # PAYLOAD_LENGTH lets no other id through


class Framer:
    """Splits a byte stream into messages, resynchronising after noise; counts in :attr:`stats`."""

    def __init__(self) -> None:
        self.stats = LinkStats()
        self._buf = bytearray()
        self._mav = mavlink.MAVLink(None, srcSystem=0, srcComponent=0)
        self._last_seq: dict[tuple[int, int], int] = {}

    @property
    def pending(self) -> int:
        """Bytes buffered: the start of a frame that is not complete yet."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Message]:
        """Add received bytes (any number) and return the messages of the frames they complete."""
        buf, stats, pos = self._buf, self.stats, 0
        buf += data
        out: list[Message] = []
        while match := _START.search(buf, pos):
            stats.garbage_bytes += match.start() - pos
            pos = match.start()
            check = self._frame_v1 if buf[pos] == STX_V1 else self._frame_v2
            size = check(buf, pos, out)
            if size == _WAIT:
                break
            if size == _REJECT:
                stats.garbage_bytes += 1
            pos += max(size, 1)
        else:
            stats.garbage_bytes += len(buf) - pos
            pos = len(buf)
        del buf[:pos]
        return out

    def _frame_v1(self, buf: bytearray, pos: int, out: list[Message]) -> int:
        """Check a MAVLink 1 frame at ``pos``; on success append its message, return its size."""
        if len(buf) - pos < _V1_HEADER:
            return _WAIT
        length, msgid = buf[pos + 1], buf[pos + 5]
        if PAYLOAD_LENGTH.get(msgid) != length:
            return _REJECT
        size = _V1_HEADER + length + 2
        if len(buf) - pos < size:
            return _WAIT
        if not _crc_ok(buf, pos + 1, pos + size - 2, CRC_EXTRA[msgid]):
            self.stats.crc_errors += 1
            return _REJECT
        seq, sysid, compid = buf[pos + 2], buf[pos + 3], buf[pos + 4]
        last = self._last_seq.get((sysid, compid))
        if last is not None and seq != (last + 1) % 256:
            self.stats.seq_gaps += 1
            self.stats.lost_frames += (seq - last - 1) % 256
        self._last_seq[(sysid, compid)] = seq
        self.stats.frames += 1
        out.append(_convert(msgid, bytes(buf[pos : pos + size]), self._mav, seq, sysid, compid))
        return size

    def _frame_v2(self, buf: bytearray, pos: int, out: list[Message]) -> int:
        """Check a MAVLink 2 GPIOX frame at ``pos``; on success append it, return its size."""
        if len(buf) - pos < _V2_HEADER:
            return _WAIT
        length, incompat = buf[pos + 1], buf[pos + 2]
        msgid = int.from_bytes(buf[pos + 7 : pos + 10], "little")
        if msgid != MSG_GPIOX or length > GPIOX_PAYLOAD_LENGTH or incompat & ~_V2_SIGNED:
            return _REJECT
        signature = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN if incompat & _V2_SIGNED else 0
        size = _V2_HEADER + length + 2 + signature
        if len(buf) - pos < size:
            return _WAIT
        if not _crc_ok(buf, pos + 1, pos + _V2_HEADER + length, GPIOX_CRC_EXTRA):
            return _REJECT
        self.stats.frames += 1
        self.stats.generation_b_frames += 1
        out.append(GenerationBFrame(msgid, buf[pos + 4], buf[pos + 5], buf[pos + 6]))
        return size
