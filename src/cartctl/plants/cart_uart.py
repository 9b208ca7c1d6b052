"""The cart's end of the serial line, as the virtual cart models it: line speed, receive ring, parser.

Three facts of the real cart decide whether a command from the PC arrives:

- **the line**: 115200 baud 8N1 carries one byte per :data:`BYTE_TIME_S` (86.8 µs), so a 60-byte
  GPIO frame takes 5.2 ms;
- **the receive ring**: the Arduino core keeps what the UART received in a 64-byte ring that holds
  :data:`RX_RING_BYTES` (63) bytes; a byte that arrives while it is full is dropped. Nothing
  empties it but a *drain*: a call of microOS's communicator ``receive()``, which reads every
  waiting byte;
- **the parser**: microOS's MAVLink parser reads a frame by its length byte. A frame with bytes
  missing swallows the start of the next one, fails its checksum and is dropped whole; the
  parser does not go back to look for a frame inside it.

:class:`LineReader` and :class:`PacedWriter` are the pseudo-terminal's two directions at line speed
(a pseudo-terminal delivers at once); :func:`fill_ring` and :class:`MicroosParser` are the pure
part, used at each drain.
"""

from __future__ import annotations

import collections
import os
import queue
import random
import select
import threading
import time

from cartctl.cart import BAUD
from cartctl.link import Framer, Gpio
from cartctl.link.dialect import STX_V1

BYTE_TIME_S = 10.0 / BAUD
"""One byte of 8N1 on the line (s): 86.8 µs."""
RX_RING_BYTES = 63
"""What the ATmega2560's serial receive ring holds (the Arduino core's 64-byte buffer)."""
_V1_OVERHEAD_AFTER_LEN = 4 + 2  # SEQ SYSID COMPID MSGID, then the two CRC bytes


def fill_ring(arrived: bytes) -> tuple[bytes, int]:
    """What a drain finds of the bytes that arrived since the previous drain.

    The ring keeps the first :data:`RX_RING_BYTES`; later ones are dropped, as the Arduino core
    drops a byte that finds the ring full.

    Returns
    -------
    kept : bytes
    dropped : int
        How many bytes were dropped.
    """
    if len(arrived) <= RX_RING_BYTES:
        return arrived, 0
    return arrived[:RX_RING_BYTES], len(arrived) - RX_RING_BYTES


class MicroosParser:
    """microOS's receive side of MAVLink 1: frames by their length byte, no resynchronisation.

    A frame starts at a start byte (0xFE) and ends ``LEN + 8`` bytes later, whatever those bytes
    are; only then is its checksum looked at (by :class:`~cartctl.link.Framer`). A frame whose
    bytes were partly dropped therefore takes in the head of the next frame and both are lost.

    Attributes
    ----------
    frames : int
        GPIO frames decoded.
    bad_frames : int
        Frames dropped for a wrong checksum or an unknown message.
    """

    def __init__(self) -> None:
        self._frame = bytearray()
        self._need = 0
        self._framer = Framer()
        self.frames = 0
        self.bad_frames = 0

    def feed(self, data: bytes) -> list[Gpio]:
        """Parse ``data``; returns the GPIO messages of the frames it completes."""
        out: list[Gpio] = []
        for byte in data:
            frame = self._frame
            if not frame:
                if byte == STX_V1:
                    frame.append(byte)
                continue
            frame.append(byte)
            if len(frame) == 2:  # the length byte
                self._need = 2 + byte + _V1_OVERHEAD_AFTER_LEN
            if len(frame) < self._need:
                continue
            messages = self._framer.feed(bytes(frame))
            gpios = [m for m in messages if isinstance(m, Gpio)]
            self.frames += len(gpios)
            out.extend(gpios)
            if not messages:  # dropped whole; the framer must not rescan it later
                self.bad_frames += 1
                self._framer = Framer()
            self._frame = bytearray()
        return out


class PacedWriter(threading.Thread):
    """Writes queued bytes to the pty master no faster than the line carries them.

    Each item is ``(not_before_s, data)``: the bytes leave at ``time.perf_counter()`` no earlier
    than ``not_before_s`` (when the cart's communication thread sends them).
    """

    CHUNK_BYTES = 8  # ~0.7 ms of line time per write

    def __init__(self, fd: int, stop: threading.Event) -> None:
        super().__init__(name="virtual-cart-writer", daemon=True)
        self.fd = fd
        self.stop_event = stop
        self.queue: queue.SimpleQueue[tuple[float, bytes]] = queue.SimpleQueue()
        self.dropped_bytes = 0
        self._line_free_s = 0.0

    def put(self, data: bytes, not_before_s: float = 0.0) -> None:
        """Queue ``data`` to leave no earlier than ``not_before_s``."""
        self.queue.put((not_before_s, data))

    def run(self) -> None:
        while not self.stop_event.is_set():
            try:
                not_before_s, data = self.queue.get(timeout=0.05)
            except queue.Empty:
                continue
            start = max(time.perf_counter(), self._line_free_s, not_before_s)
            for offset in range(0, len(data), self.CHUNK_BYTES):
                chunk = data[offset : offset + self.CHUNK_BYTES]
                due = start + (offset + len(chunk)) * BYTE_TIME_S
                delay = due - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
                if self.stop_event.is_set():
                    return
                try:
                    os.write(self.fd, chunk)
                except BlockingIOError:  # nobody reads the port: the bytes are lost, as on a UART
                    self.dropped_bytes += len(chunk)
                except OSError:
                    return
            self._line_free_s = start + len(data) * BYTE_TIME_S


class LineReader(threading.Thread):
    """Reads what the host writes and stamps each byte with when the line delivered it.

    Parameters
    ----------
    fd : int
        The pty master.
    stop : threading.Event
    reply_jitter_s : float
        Each write of the host is held back by a random 0 .. ``reply_jitter_s`` before it goes on
        the line: a host whose replies come late by varying amounts.
    seed : int, optional
        Seeds the jitter.
    """

    def __init__(
        self,
        fd: int,
        stop: threading.Event,
        *,
        reply_jitter_s: float = 0.0,
        seed: int | None = None,
    ) -> None:
        super().__init__(name="virtual-cart-reader", daemon=True)
        self.fd = fd
        self.stop_event = stop
        self.reply_jitter_s = float(reply_jitter_s)
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._arrived: collections.deque[tuple[float, int]] = collections.deque()
        self._line_free_s = 0.0
        self.last_byte_at_s: float | None = None
        """``time.perf_counter`` when the last byte the host wrote is (or will be) through."""

    def run(self) -> None:
        while not self.stop_event.is_set():
            try:
                ready, _, _ = select.select([self.fd], [], [], 0.05)
                if not ready:
                    continue
                data = os.read(self.fd, 4096)
            except OSError:  # the pty went away (cable pulled, cart stopped)
                return
            if not data:
                return
            now = time.perf_counter()
            if self.reply_jitter_s > 0.0:
                now += self._rng.uniform(0.0, self.reply_jitter_s)
            self.deliver(data, now)

    def deliver(self, data: bytes, written_s: float) -> None:
        """Put ``data``, written by the host at ``written_s``, on the line behind what is on it."""
        start = max(written_s, self._line_free_s)
        with self._lock:
            for i, byte in enumerate(data):
                self._arrived.append((start + (i + 1) * BYTE_TIME_S, byte))
            self._line_free_s = start + len(data) * BYTE_TIME_S
            self.last_byte_at_s = self._line_free_s

    def take(self, until_s: float) -> bytes:
        """Every byte whose last bit has arrived by ``until_s``, in order."""
        out = bytearray()
        with self._lock:
            while self._arrived and self._arrived[0][0] <= until_s:
                out.append(self._arrived.popleft()[1])
        return bytes(out)
