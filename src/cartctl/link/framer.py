"""Bytes in, messages out (pure, no I/O): the decoded messages, :class:`Framer` and the text lines.

:class:`Framer` checks generation-A frames (MAVLink 1) against their payload length and CRC_EXTRA
and recognises generation-B GPIOX frames (MAVLink 2). On a header that fits no known message, or a
CRC mismatch, only the start byte is dropped, so a false start in line noise never swallows the
real frame that follows (pymavlink's own parser can). Every message carries the frame's ``seq``,
``sysid`` and ``compid`` last, with defaults, so that tests can build messages without a frame.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any, TypeAlias

import cartctl.link.dialect as dialect
from cartctl.link.vendor import microos_mavlink as mavlink

BUTTON_EVENT_BASE = 1000
"""EVENT type of QRC's button 0; buttons 0..7 are 1000..1007."""


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
    """Joins PRINT texts into lines.

    The firmware ends lines with "\\r\\n" and splits text over 32-byte PRINT frames regardless of
    line boundaries. A line ends at "\\n"; every "\\r" is dropped, so a "\\r\\n" split over two
    frames still ends exactly one line.
    """

    def __init__(self) -> None:
        self._partial: list[str] = []

    def feed(self, text: str) -> list[str]:
        """Add a fragment; return the lines it completes (oldest first, without line endings)."""
        pieces = text.replace("\r", "").split("\n")
        if len(pieces) == 1:
            if pieces[0]:
                self._partial.append(pieces[0])
            return []
        lines = ["".join([*self._partial, pieces[0]]), *pieces[1:-1]]
        self._partial = [pieces[-1]] if pieces[-1] else []
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
    if msgid == dialect.MSG_THREAD_INFO:
        return ThreadInfo(frame[_V1_HEADER:-2], *header)
    m: Any = mav.decode(bytearray(frame))
    if msgid == dialect.MSG_GPIO:
        return Gpio(m.time, tuple(m.gpio_float), tuple(m.gpio_int), *header)
    if msgid == dialect.MSG_HEARTBEAT:
        return Heartbeat(m.time, m.type, bytes(m.data), m.mavlink_version, *header)
    if msgid == dialect.MSG_EVENT:
        return Event(m.type, *header)
    assert msgid == dialect.MSG_PRINT  # PAYLOAD_LENGTH lets no other id through
    return PrintText(m.text, *header)


class Framer:
    """Splits a byte stream into microOS messages, resynchronising after noise; counts in
    :attr:`stats`."""

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
        buf = self._buf
        buf += data
        stats = self.stats
        out: list[Message] = []
        pos = 0
        while True:
            match = _START.search(buf, pos)
            start = len(buf) if match is None else match.start()
            stats.garbage_bytes += start - pos
            pos = start
            if match is None:
                break
            check = self._frame_v1 if buf[pos] == dialect.STX_V1 else self._frame_v2
            size = check(buf, pos, out)
            if size == _WAIT:
                break
            if size == _REJECT:
                stats.garbage_bytes += 1
                size = 1
            pos += size
        del buf[:pos]
        return out

    def _frame_v1(self, buf: bytearray, pos: int, out: list[Message]) -> int:
        """Check a MAVLink 1 frame at ``pos``; on success append its message, return its size."""
        if len(buf) - pos < _V1_HEADER:
            return _WAIT
        length, msgid = buf[pos + 1], buf[pos + 5]
        if dialect.PAYLOAD_LENGTH.get(msgid) != length:
            return _REJECT
        size = _V1_HEADER + length + 2
        if len(buf) - pos < size:
            return _WAIT
        if not _crc_ok(buf, pos + 1, pos + size - 2, dialect.CRC_EXTRA[msgid]):
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
        if (
            msgid != dialect.MSG_GPIOX
            or length > dialect.GPIOX_PAYLOAD_LENGTH
            or incompat & ~_V2_SIGNED
        ):
            return _REJECT
        signature = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN if incompat & _V2_SIGNED else 0
        size = _V2_HEADER + length + 2 + signature
        if len(buf) - pos < size:
            return _WAIT
        if not _crc_ok(buf, pos + 1, pos + _V2_HEADER + length, dialect.GPIOX_CRC_EXTRA):
            return _REJECT
        self.stats.frames += 1
        self.stats.generation_b_frames += 1
        out.append(GenerationBFrame(msgid, buf[pos + 4], buf[pos + 5], buf[pos + 6]))
        return size
