"""The cart's end of the serial line as the virtual cart models it (docs/serial-protocol.md §4):
the line's byte time (a pseudo-terminal delivers at once), the Mega's USB bridge, the receive ring
and microOS's parser.
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import queue
import random
import select
import threading
import time
from collections.abc import Callable, Iterable

from cartctl.link.bridge import LEGACY_BAUD
from cartctl.link.dialect import STX_V1, Framer, Gpio

RX_RING_BYTES = 63  # the Arduino core's 64-byte ring
BRIDGE_RX_RING_BYTES = 255  # the bridge is built with -DSERIAL_RX_BUFFER_SIZE=256
USB_FLUSH_PERIOD_S = 256 * 256 / 16e6  # the 16U2's Timer0 overflows every 4.096 ms
USB_FLUSH_BYTES = 96  # 3/4 of the 16U2's 128-byte ring
USB_FRAME_S = 0.001  # a full-speed USB frame
GPIO_FRAME_BYTES = 60  # 52 bytes of payload and 8 of MAVLink 1


def next_on_grid(t: float, phase_s: float, period_s: float) -> float:
    """The first instant of the grid ``phase_s + n·period_s`` at or after ``t`` (s)."""
    return phase_s + math.ceil((t - phase_s) / period_s - 1e-12) * period_s


def byte_time_s(baud: int) -> float:
    """One byte of 8N1 at ``baud`` (s)."""
    return 10.0 / float(baud)


BYTE_TIME_S = byte_time_s(LEGACY_BAUD)


class UsbBridge:
    """When the cart's bytes reach the PC through the Mega's ATmega16U2 (pure; times in s): they
    wait for its 4.096 ms flush or its 96-byte threshold, then for the PC's next 1 ms USB frame
    (the phases place both grids)."""

    def __init__(self, flush_phase_s: float = 0.0, frame_phase_s: float = 0.0) -> None:
        self.flush_phase_s = float(flush_phase_s)
        self.frame_phase_s = float(frame_phase_s)
        self._waiting: list[tuple[float, int]] = []  # (through the AVR's UART, byte)

    def feed(self, byte_times: Iterable[tuple[float, int]]) -> list[tuple[float, bytes]]:
        """``(at_pc_s, data)`` of the flushes that bytes through the UART at these times complete."""
        out: list[tuple[float, bytes]] = []
        for t, byte in byte_times:
            out += self.flush_due(t)
            self._waiting.append((t, byte))
            if len(self._waiting) > USB_FLUSH_BYTES:
                out.append(self._flush(t))
        return out

    @property
    def pending_flush_s(self) -> float | None:
        """When the bytes waiting now go out (their timer overflow), None when none wait."""
        if not self._waiting:
            return None
        return next_on_grid(self._waiting[0][0], self.flush_phase_s, USB_FLUSH_PERIOD_S)

    def flush_due(self, now_s: float) -> list[tuple[float, bytes]]:
        """The waiting bytes, if their flush is due by ``now_s``."""
        due = self.pending_flush_s
        return [self._flush(due)] if due is not None and due <= now_s else []

    def _flush(self, at_s: float) -> tuple[float, bytes]:
        data = bytes(byte for _, byte in self._waiting)
        self._waiting = []
        return next_on_grid(at_s, self.frame_phase_s, USB_FRAME_S), data  # the PC's next frame


def fill_ring(arrived: bytes, capacity: int = RX_RING_BYTES) -> tuple[bytes, int]:
    """What a drain finds of the bytes that arrived since the previous one, and how many the full
    ring dropped (it keeps the first ``capacity`` until a drain empties it)."""
    return arrived[:capacity], max(0, len(arrived) - capacity)


class MicroosParser:
    """microOS's receive side of MAVLink 1: a frame is the ``LEN + 8`` bytes from a start byte,
    whatever they are (no resynchronisation), then its checksum is checked; counts GPIO ``frames``
    and ``bad_frames``."""

    def __init__(self) -> None:
        self._frame = bytearray()
        self._need = 0
        self._framer = Framer()
        self.frames = 0
        self.bad_frames = 0

    def feed(self, data: bytes) -> list[Gpio]:
        """The GPIO messages of the frames ``data`` completes."""
        out: list[Gpio] = []
        for byte in data:
            frame = self._frame
            if frame or byte == STX_V1:
                frame.append(byte)
            if len(frame) < 2:
                continue
            if len(frame) == 2:  # the length byte
                self._need = 2 + byte + 6  # SEQ SYSID COMPID MSGID, payload, CRC
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


class _PtyThread(threading.Thread):
    """One direction of the line on the pty master, one byte per ``byte_s``."""

    def __init__(self, name: str, fd: int, stop: threading.Event, byte_s: float) -> None:
        super().__init__(name=name, daemon=True)
        self.fd = fd
        self.stop_event = stop
        self.byte_s = float(byte_s)
        self._line_free_s = 0.0
        self.rate_ok: Callable[[], bool] = lambda: True  # the host's port at the cart's rate?

    def _on_line(self, not_before_s: float, data: bytes) -> list[tuple[float, int]]:
        """Put ``data`` on the line behind what is on it: when each byte is through (s)."""
        start = max(not_before_s, self._line_free_s)
        self._line_free_s = start + len(data) * self.byte_s
        return [(start + (i + 1) * self.byte_s, byte) for i, byte in enumerate(data)]


class PacedWriter(_PtyThread):
    """Writes queued bytes to the pty master when the line (and ``usb``) would deliver them, each
    item no earlier than its ``not_before_s`` (``time.perf_counter``); :attr:`deliveries`:
    ``(through_uart_s, at_pc_s)`` of tracked items."""

    def __init__(
        self, fd: int, stop: threading.Event, byte_s: float, usb: UsbBridge | None
    ) -> None:
        super().__init__("virtual-cart-writer", fd, stop, byte_s)
        self.usb = usb
        self.queue: queue.SimpleQueue[tuple[float, bytes, bool]] = queue.SimpleQueue()
        self._tracked: list[tuple[int, float]] = []  # (byte count at its end, its end), in transit
        self._fed = self._passed = 0  # bytes put on the line, and delivered to the PC
        self.deliveries: collections.deque[tuple[float, float]] = collections.deque(maxlen=4096)
        self._out: collections.deque[tuple[float, bytes]] = collections.deque()

    def put(self, data: bytes, not_before_s: float = 0.0, *, track: bool = False) -> None:
        """Queue ``data``; ``track``: note in :attr:`deliveries` when it reaches the PC."""
        self.queue.put((not_before_s, data, track))

    def _take(self, not_before_s: float, data: bytes, track: bool) -> None:
        times = self._on_line(not_before_s, data)
        self._fed += len(data)
        if track:
            self._tracked.append((self._fed, self._line_free_s))
        flushes = [(self._line_free_s, data)] if self.usb is None else self.usb.feed(times)
        for at_s, chunk in flushes:
            self._deliver(at_s, chunk)

    def _deliver(self, at_s: float, chunk: bytes) -> None:
        """``chunk`` (a USB flush) reaches the PC at ``at_s``, with every tracked item in it."""
        self._out.append((at_s, chunk))
        self._passed += len(chunk)
        while self._tracked and self._tracked[0][0] <= self._passed:
            self.deliveries.append((self._tracked.pop(0)[1], at_s))

    def run(self) -> None:
        while not self.stop_event.is_set():
            now = time.perf_counter()
            if self.usb is not None:
                for at_s, chunk in self.usb.flush_due(now):
                    self._deliver(at_s, chunk)
            while self._out and self._out[0][0] <= now:
                _, data = self._out.popleft()
                if not self.rate_ok():
                    data = bytes(random.getrandbits(8) for _ in data)
                try:
                    os.write(self.fd, data)
                except BlockingIOError:  # nobody reads the port: the bytes are lost, as on a UART
                    pass
                except OSError:
                    return
            next_out = self._out[0][0] if self._out else None
            next_flush = self.usb.pending_flush_s if self.usb is not None else None
            due = [t - now for t in (next_out, next_flush) if t is not None]
            wait = min([0.05, *due])  # until something is due, or a new item comes
            with contextlib.suppress(queue.Empty):
                self._take(*self.queue.get(timeout=max(wait, 0.0)))


class LineReader(_PtyThread):
    """Reads what the host writes (from the pty master) and stamps each byte with when the line
    delivered it. Each write is held back a random 0 .. ``reply_jitter_s`` (seeded by ``seed``)
    and, with the USB bridge, until the next 1 ms USB frame."""

    def __init__(
        self,
        fd: int,
        stop: threading.Event,
        byte_s: float,
        usb: UsbBridge | None,
        reply_jitter_s: float,
        seed: int | None,
    ) -> None:
        super().__init__("virtual-cart-reader", fd, stop, byte_s)
        self.usb = usb
        self.reply_jitter_s = float(reply_jitter_s)
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._arrived: collections.deque[tuple[float, int]] = collections.deque()
        self.last_byte_at_s: float | None = None  # when the host's last byte is through the line
        # when each recent 60-byte frame of the host was through the line (its last byte)
        self.through_s: collections.deque[float] = collections.deque(maxlen=1 << 16)
        self._count = 0

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
            if self.usb is not None:  # out at the next USB frame
                now = next_on_grid(now, self.usb.frame_phase_s, USB_FRAME_S)
            if not self.rate_ok():
                data = bytes(self._rng.getrandbits(8) for _ in data)
            self.deliver(data, now)

    def deliver(self, data: bytes, written_s: float) -> None:
        """Put ``data``, written by the host at ``written_s``, on the line behind what is on it."""
        with self._lock:
            self._arrived.extend(self._on_line(written_s, data))
            self.last_byte_at_s = self._line_free_s
            self._count += len(data)
            while self._count >= GPIO_FRAME_BYTES:  # the host writes whole 60-byte GPIO frames
                self._count -= GPIO_FRAME_BYTES
                self.through_s.append(self._line_free_s - self._count * self.byte_s)

    def take(self, until_s: float) -> bytes:
        """Every byte whose last bit has arrived by ``until_s``, in order."""
        out = bytearray()
        with self._lock:
            while self._arrived and self._arrived[0][0] <= until_s:
                out.append(self._arrived.popleft()[1])
        return bytes(out)
