"""A resynchronising stream framer for the cart's serial link (pure: no I/O).

:class:`Framer` takes bytes as they arrive, in chunks of any size, and returns the messages of the
complete, valid frames among them. It recognises

- generation A, MAVLink 1 (start byte 0xFE): HEARTBEAT, THREAD_INFO, GPIO, EVENT and PRINT, each
  checked against its payload length and CRC_EXTRA;
- generation B, MAVLink 2 (start byte 0xFD): GPIOX only, reported as :class:`GenerationBFrame`.

On a header that does not fit a known message, or a CRC mismatch, only the start byte is dropped and
the scan resumes at the next byte, so a false start in line noise never swallows the real frame that
follows (pymavlink's own parser can). Every byte that is not part of a valid frame is counted once
in :attr:`LinkStats.garbage_bytes`.

The framer finds and checks frames itself (header lengths, X.25 CRC and CRC_EXTRA come from the
generated dialect module, :mod:`cartctl.link.vendor.microos_mavlink`, through
:mod:`~cartctl.link.dialect`); that module's ``MAVLink.decode`` then unpacks the payload of each
valid generation-A frame.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

from cartctl.link.dialect import (
    CRC_EXTRA,
    GPIOX_CRC_EXTRA,
    GPIOX_PAYLOAD_LENGTH,
    MSG_EVENT,
    MSG_GPIO,
    MSG_GPIOX,
    MSG_HEARTBEAT,
    MSG_PRINT,
    MSG_THREAD_INFO,
    PAYLOAD_LENGTH,
    STX_V1,
)
from cartctl.link.messages import (
    Event,
    GenerationBFrame,
    Gpio,
    Heartbeat,
    Message,
    PrintText,
    ThreadInfo,
)
from cartctl.link.vendor import microos_mavlink as mavlink

__all__ = ["Framer", "LinkStats"]

_START = re.compile(rb"[\xfd\xfe]")
_V1_HEADER = mavlink.HEADER_LEN_V1
_V2_HEADER = mavlink.HEADER_LEN_V2
_CRC_BYTES = 2
_V2_SIGNATURE = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN
_V2_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_SEQ_MODULO = 256

_WAIT = 0
"""Return value of a frame check: the frame is incomplete, wait for more bytes."""
_REJECT = -1
"""Return value of a frame check: the start byte does not begin a valid frame."""

_V1_EXTRA = {msgid: bytes([extra]) for msgid, extra in CRC_EXTRA.items()}
_V2_EXTRA = bytes([GPIOX_CRC_EXTRA])


@dataclass
class LinkStats:
    """Counters of a link's receive side.

    Attributes
    ----------
    frames
        Valid frames decoded (both generations).
    crc_errors
        Generation-A frames with a plausible header but a wrong checksum.
    garbage_bytes
        Bytes that belong to no valid frame, each counted once.
    seq_gaps
        Times the sequence number of a source (sysid, compid) did not advance by exactly one.
    lost_frames
        Frames missing according to those gaps.
    generation_b_frames
        Valid MAVLink 2 GPIOX frames (a generation-B cart).
    """

    frames: int = 0
    crc_errors: int = 0
    garbage_bytes: int = 0
    seq_gaps: int = 0
    lost_frames: int = 0
    generation_b_frames: int = 0

    def to_dict(self) -> dict[str, int]:
        """The counters by name."""
        return asdict(self)


def _crc_ok(buf: bytearray, start: int, crc_at: int, extra: bytes) -> bool:
    """Whether the CRC at ``buf[crc_at:crc_at + 2]`` matches ``buf[start:crc_at]`` + ``extra``."""
    crc = mavlink.x25crc(bytes(buf[start:crc_at]) + extra).crc
    return crc == buf[crc_at] | (buf[crc_at + 1] << 8)


def _convert(
    msgid: int, frame: bytes, mav: mavlink.MAVLink, seq: int, sysid: int, compid: int
) -> Message:
    """The message of a checked generation-A frame; pymavlink's module unpacks the payload."""
    if msgid == MSG_THREAD_INFO:
        return ThreadInfo(frame[_V1_HEADER:-_CRC_BYTES], seq, sysid, compid)
    decoded: Any = mav.decode(bytearray(frame))
    if msgid == MSG_GPIO:
        return Gpio(
            decoded.time, tuple(decoded.gpio_float), tuple(decoded.gpio_int), seq, sysid, compid
        )
    if msgid == MSG_HEARTBEAT:
        return Heartbeat(
            decoded.time,
            decoded.type,
            bytes(decoded.data),
            decoded.mavlink_version,
            seq,
            sysid,
            compid,
        )
    if msgid == MSG_EVENT:
        return Event(decoded.type, seq, sysid, compid)
    if msgid == MSG_PRINT:
        return PrintText(decoded.text, seq, sysid, compid)
    raise AssertionError(f"no conversion for message id {msgid}")  # PAYLOAD_LENGTH keeps it out


class Framer:
    """Splits a byte stream into microOS messages, resynchronising after noise.

    Attributes
    ----------
    stats : LinkStats
        Counters, updated by every :meth:`feed`.
    """

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
        """Add received bytes and return the messages of the frames they complete, in order.

        Parameters
        ----------
        data
            The next bytes of the stream, any number.

        Returns
        -------
        list[Message]
            The decoded messages (possibly none).
        """
        buf = self._buf
        buf += data
        stats = self.stats
        out: list[Message] = []
        pos = 0
        while True:
            match = _START.search(buf, pos)
            if match is None:
                stats.garbage_bytes += len(buf) - pos
                pos = len(buf)
                break
            start = match.start()
            stats.garbage_bytes += start - pos
            pos = start
            if buf[pos] == STX_V1:
                size = self._frame_v1(buf, pos, out)
            else:
                size = self._frame_v2(buf, pos, out)
            if size == _WAIT:
                break
            if size == _REJECT:
                stats.garbage_bytes += 1
                pos += 1
            else:
                pos += size
        del buf[:pos]
        return out

    def _frame_v1(self, buf: bytearray, pos: int, out: list[Message]) -> int:
        """Check a MAVLink 1 frame at ``pos``; on success append its message, return its size."""
        if len(buf) - pos < _V1_HEADER:
            return _WAIT
        length = buf[pos + 1]
        msgid = buf[pos + 5]
        if PAYLOAD_LENGTH.get(msgid) != length:
            return _REJECT
        size = _V1_HEADER + length + _CRC_BYTES
        if len(buf) - pos < size:
            return _WAIT
        crc_at = pos + _V1_HEADER + length
        if not _crc_ok(buf, pos + 1, crc_at, _V1_EXTRA[msgid]):
            self.stats.crc_errors += 1
            return _REJECT
        seq, sysid, compid = buf[pos + 2], buf[pos + 3], buf[pos + 4]
        self._count_seq(seq, sysid, compid)
        self.stats.frames += 1
        out.append(_convert(msgid, bytes(buf[pos : pos + size]), self._mav, seq, sysid, compid))
        return size

    def _frame_v2(self, buf: bytearray, pos: int, out: list[Message]) -> int:
        """Check a MAVLink 2 GPIOX frame at ``pos``; on success append it, return its size."""
        if len(buf) - pos < _V2_HEADER:
            return _WAIT
        length = buf[pos + 1]
        incompat = buf[pos + 2]
        msgid = buf[pos + 7] | (buf[pos + 8] << 8) | (buf[pos + 9] << 16)
        if msgid != MSG_GPIOX or length > GPIOX_PAYLOAD_LENGTH or incompat & ~_V2_SIGNED:
            return _REJECT
        size = _V2_HEADER + length + _CRC_BYTES + (_V2_SIGNATURE if incompat & _V2_SIGNED else 0)
        if len(buf) - pos < size:
            return _WAIT
        if not _crc_ok(buf, pos + 1, pos + _V2_HEADER + length, _V2_EXTRA):
            return _REJECT
        self.stats.frames += 1
        self.stats.generation_b_frames += 1
        out.append(GenerationBFrame(msgid, buf[pos + 4], buf[pos + 5], buf[pos + 6]))
        return size

    def _count_seq(self, seq: int, sysid: int, compid: int) -> None:
        key = (sysid, compid)
        last = self._last_seq.get(key)
        if last is not None and seq != (last + 1) % _SEQ_MODULO:
            self.stats.seq_gaps += 1
            self.stats.lost_frames += (seq - last - 1) % _SEQ_MODULO
        self._last_seq[key] = seq
