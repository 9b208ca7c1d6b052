"""The virtual cart: the physical simulator behind a pseudo-terminal, speaking like the bridge sketch.

``cartctl virtual-cart`` runs one in the foreground and prints its port; ``--plant virtual`` starts
one inside the process and drives it through :class:`~cartctl.plants.serial_cart.SerialCart`, so the
real serial code path (pyserial, framing, the bridge contract, the faults) runs with no hardware.

It keeps the firmware's order within each 10 ms tick (``docs/serial-protocol.md`` §2)::

    io()       the physics advances one tick under the voltage stored at the previous tick,
               and the encoders are read
    control()  the bridge logic (:class:`~cartctl.plants.bridge_firmware.BridgeFirmware`)
    receive    every GPIO whose last byte has arrived by now (on the cart's schedule: a tick
               the host's load starts late looks as early as an on-time one would) overwrites
               the held channels
    send       one GPIO with what control() wrote (a HEARTBEAT every 1.1 s as well)

and the line's speed: 115200 baud 8N1 is 86.8 µs per byte in each direction. A pseudo-terminal
delivers at once, so a writer thread releases outgoing bytes at that rate, and incoming bytes count
as received only once the line could have carried them. Three threads: ticks, reader, writer.

Faults (:class:`CartFaults`) are injected on the way out: garbage bursts between frames, corrupted
frames, a stall (the cart stops ticking and sending, the port stays open) and a pulled cable (the
port vanishes).
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
import tty
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

from cartctl.errors import InputError
from cartctl.link import Encoder, Framer, Gpio, encode_gpiox_v2
from cartctl.plants.base import Measurement
from cartctl.plants.bridge_firmware import TICK_MODULO, BridgeFirmware, CartIO
from cartctl.plants.physics import PhysicsPlant
from cartctl.plants.serial_cart import SerialCart

BAUD = 115200
BYTE_TIME_S = 10.0 / BAUD
"""One byte of 8N1 on the line (s): 86.8 µs."""
HEARTBEAT_PERIOD_S = 1.1
READY_TEXT = "cartctl bridge ready"


@dataclass(frozen=True)
class CartFaults:
    """Faults the virtual cart injects.

    Attributes
    ----------
    garbage : float
        Fraction of outgoing frames preceded by a burst of 1-16 random bytes.
    corrupt : float
        Fraction of outgoing frames with one byte changed (their CRC fails).
    stall_after_s : float or None
        This long (s) after the host's first frame, the cart stops: no ticks, nothing sent, port
        open.
    pull_after_s : float or None
        This long (s) after the host's first frame, the cable is pulled: the port vanishes.
    generation : str
        'a' (MAVLink 1, GPIO: what the bridge sketch speaks) or 'b' (MAVLink 2, GPIOX: the newer
        firmware, which cartctl refuses).
    """

    garbage: float = 0.0
    corrupt: float = 0.0
    stall_after_s: float | None = None
    pull_after_s: float | None = None
    generation: str = "a"

    KEYS = ("garbage", "corrupt", "stall", "pull", "generation")

    def __post_init__(self) -> None:
        for name in ("garbage", "corrupt"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(f"fault '{name}' must be a fraction in [0, 1], got {value}")
        for name in ("stall_after_s", "pull_after_s"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0.0):
                raise InputError(f"fault time '{name}' must be >= 0 s, got {value}")
        if self.generation not in ("a", "b"):
            raise InputError(f"generation must be 'a' or 'b', got '{self.generation}'")

    @classmethod
    def parse(cls, text: str) -> CartFaults:
        """Faults from ``key=value,...``: garbage=0.05, corrupt=0.05, stall=S, pull=S, generation=b."""
        faults = cls()
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, value = item.partition("=")
            key = key.strip()
            if not sep or key not in cls.KEYS:
                raise InputError(
                    f"bad fault '{item}'; expected key=value with key in {', '.join(cls.KEYS)}"
                )
            if key == "generation":
                faults = replace(faults, generation=value.strip().lower())
                continue
            try:
                number = float(value)
            except ValueError:
                raise InputError(f"fault '{key}' needs a number, got '{value}'") from None
            field = {"stall": "stall_after_s", "pull": "pull_after_s"}.get(key, key)
            faults = replace(faults, **{field: number})
        return faults


class CartFirmware(Protocol):
    """What the virtual cart runs in ``control()``, with the GPIO channels it holds and writes."""

    out_floats: list[float]
    out_ints: list[int]

    def receive(self, floats: Sequence[float], ints: Sequence[int]) -> None:
        """A GPIO from the host overwrites the held input channels."""
        ...

    def control(self, io: CartIO) -> tuple[float, float]:
        """One tick: returns the voltages (V) for the next ``io()``; fills the output channels."""
        ...


class _PacedWriter(threading.Thread):
    """Writes queued bytes to the pty master no faster than the line carries them."""

    CHUNK_BYTES = 8  # ~0.7 ms of line time per write

    def __init__(self, fd: int, stop: threading.Event) -> None:
        super().__init__(name="virtual-cart-writer", daemon=True)
        self.fd = fd
        self.stop_event = stop
        self.queue: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self.dropped_bytes = 0
        self._line_free_s = 0.0

    def run(self) -> None:
        while not self.stop_event.is_set():
            try:
                data = self.queue.get(timeout=0.05)
            except queue.Empty:
                continue
            start = max(time.perf_counter(), self._line_free_s)
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


class _LineReader(threading.Thread):
    """Reads what the host writes and stamps each byte with when the line delivered it."""

    def __init__(self, fd: int, stop: threading.Event) -> None:
        super().__init__(name="virtual-cart-reader", daemon=True)
        self.fd = fd
        self.stop_event = stop
        self._lock = threading.Lock()
        self._arrived: collections.deque[tuple[float, bytes]] = collections.deque()
        self._line_free_s = 0.0

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
            start = max(now, self._line_free_s)
            with self._lock:
                for i in range(len(data)):
                    self._arrived.append((start + (i + 1) * BYTE_TIME_S, data[i : i + 1]))
            self._line_free_s = start + len(data) * BYTE_TIME_S

    def take(self, now_s: float) -> bytes:
        """Every byte whose last bit has arrived by ``now_s``."""
        out = bytearray()
        with self._lock:
            while self._arrived and self._arrived[0][0] <= now_s:
                out += self._arrived.popleft()[1]
        return bytes(out)


class VirtualCart:
    """The physical simulator behind a pseudo-terminal, speaking the bridge contract.

    Parameters
    ----------
    preset : str
        Physics preset, 'ground' or 'air'.
    noise_std_rad_s : float
        Extra measurement noise of the simulator (rad/s).
    seed : int, optional
        Seeds the simulator's noise and the fault injection.
    faults : CartFaults, optional
        Faults to inject (none by default).
    period_s : float
        The tick (s), 0.01 as microOS.
    firmware : CartFirmware, optional
        What runs in ``control()``: the bridge sketch (default), or a controller on the cart.

    Use as a context manager, or :meth:`start` and :meth:`stop`. :attr:`port` is the path to
    open (``/dev/pts/N``).
    """

    def __init__(
        self,
        preset: str = "ground",
        *,
        noise_std_rad_s: float = 0.0,
        seed: int | None = None,
        faults: CartFaults | None = None,
        period_s: float = 0.01,
        firmware: CartFirmware | None = None,
    ) -> None:
        self.physics = PhysicsPlant(preset, noise_std_rad_s=noise_std_rad_s, seed=seed)
        self.preset = preset
        self.faults = faults or CartFaults()
        self.period_s = float(period_s)
        self.firmware: CartFirmware = firmware if firmware is not None else BridgeFirmware()
        self._rng = random.Random(seed)
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing before the host configures the port
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._writer = _PacedWriter(self._master, self._stop)
        self._reader = _LineReader(self._master, self._stop)
        self._ticker = threading.Thread(target=self._run, name="virtual-cart", daemon=True)
        self.ticks = 0
        self.true_speeds: dict[int, tuple[float, float]] = {}
        """True wheel speeds (rad/s) at each recent tick, by the tick counter the cart sends."""
        self.frames_received = 0
        self.last_voltage_v: tuple[float, float] = (0.0, 0.0)
        self.state = "idle"
        self.first_frame_at_s: float | None = None
        """``time.perf_counter`` when the host's first GPIO arrived (faults count from there)."""
        self.fault_at_s: float | None = None
        """``time.perf_counter`` when the injected stall or pulled cable began."""

    def __enter__(self) -> VirtualCart:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> None:
        """Boot the cart: the threads start, the first HEARTBEAT and the PRINT line go out."""
        self._writer.start()
        self._reader.start()
        self._ticker.start()

    def stop(self) -> None:
        """Stop the threads and close the pseudo-terminal."""
        self._stop.set()
        for thread in (self._ticker, self._writer, self._reader):
            if thread.is_alive() and thread is not threading.current_thread():
                thread.join(timeout=1.0)
        self._close_fds()

    def wait(self) -> None:
        """Block until the cart stops (Ctrl-C, a pulled cable)."""
        while self._ticker.is_alive():
            self._ticker.join(timeout=0.2)

    def arm_faults(self) -> None:
        """Start the stall/pull clock now, for a host that never sends (``cartctl monitor``)."""
        if self.first_frame_at_s is None:
            self.first_frame_at_s = time.perf_counter()

    def wait_seconds(self, seconds: float) -> None:
        """Block for ``seconds`` or until the cart stops."""
        self._ticker.join(timeout=seconds)

    def wait_ticks(self, n: int, timeout_s: float = 0.5) -> None:
        """Block until the cart has run ``n`` more ticks (or stopped, or ``timeout_s`` passed)."""
        target = self.ticks + n
        deadline = time.perf_counter() + timeout_s
        while self.ticks < target and self._ticker.is_alive() and time.perf_counter() < deadline:
            time.sleep(0.002)

    def _close_fds(self) -> None:
        for name in ("_master", "_slave"):
            fd = getattr(self, name)
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
                setattr(self, name, -1)

    # -- the firmware ---------------------------------------------------------------------------

    def _send(self, frame: bytes) -> None:
        faults, rng = self.faults, self._rng
        if faults.garbage and rng.random() < faults.garbage:
            self._writer.queue.put(bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 16))))
        if faults.corrupt and rng.random() < faults.corrupt:
            data = bytearray(frame)
            i = rng.randrange(1, len(data))  # any byte after the start byte
            data[i] ^= rng.randint(1, 255)
            frame = bytes(data)
        self._writer.queue.put(frame)

    def _run(self) -> None:
        encoder = Encoder(sysid=0, compid=0)
        framer = Framer()
        physics, firmware = self.physics, self.firmware
        rad_per_count = 2.0 * math.pi / physics.params.counts_per_rev
        boot = time.perf_counter()
        self.state = "running"
        generation_a = self.faults.generation == "a"
        if generation_a:  # a generation-B cart speaks MAVLink 2 only (its GPIOX frames, below)
            self._writer.queue.put(encoder.heartbeat(0))
            ready = getattr(self.firmware, "ready_text", READY_TEXT)
            for frame in encoder.print_text(ready + "\r\n"):
                self._writer.queue.put(frame)
        next_heartbeat = boot + HEARTBEAT_PERIOD_S
        measurement = physics.reset()
        voltage = (0.0, 0.0)
        j = 0
        faults = self.faults
        while not self._stop.is_set():
            deadline = boot + (j + 1) * self.period_s
            delay = deadline - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            now = time.perf_counter()
            elapsed = now - boot
            driven = 0.0 if self.first_frame_at_s is None else now - self.first_frame_at_s
            if faults.pull_after_s is not None and driven >= faults.pull_after_s:
                self.state = "cable pulled"
                self.fault_at_s = time.perf_counter()
                self._stop.set()
                self._close_fds()
                return
            if faults.stall_after_s is not None and driven >= faults.stall_after_s:
                self.state = "stalled"
                self.fault_at_s = time.perf_counter()
                self._stop.wait()
                return
            # io(): the voltage stored at the previous tick drives this one; read the encoders
            if j > 0:
                measurement = physics.step(*voltage)
            counts = physics.encoder_counts
            applied = physics.applied_voltage_v
            io = CartIO(
                measurement.speed_a_rad_s, measurement.speed_b_rad_s, applied[0], applied[1],
                counts[0] * rad_per_count, counts[1] * rad_per_count,
            )  # fmt: skip
            tick_counter = firmware.tick
            self.true_speeds[tick_counter] = (
                measurement.true_speed_a_rad_s or 0.0,
                measurement.true_speed_b_rad_s or 0.0,
            )
            self.true_speeds.pop((tick_counter - 512) % TICK_MODULO, None)  # keep the recent ones
            voltage = firmware.control(io)
            self.last_voltage_v = voltage
            # the communication thread: receive everything that has arrived, then send. "By now"
            # is on the cart's own schedule: a tick this thread starts late (a busy host) must not
            # take in bytes that arrived after the moment an on-time cart would have looked.
            receive_at = deadline + (time.perf_counter() - now)
            for message in framer.feed(self._reader.take(receive_at)):
                if isinstance(message, Gpio):
                    firmware.receive(message.floats, message.ints)
                    self.frames_received += 1
                    if self.first_frame_at_s is None:
                        self.first_frame_at_s = now
            time_ms = int(elapsed * 1000.0) & 0xFFFFFFFF
            if not generation_a:
                floats12 = [*firmware.out_floats, *(float(v) for v in firmware.out_ints)]
                self._send(encode_gpiox_v2(time_ms, floats12, seq=j % 256))
            else:
                self._send(encoder.gpio(time_ms, firmware.out_floats, firmware.out_ints))
            if generation_a and now >= next_heartbeat:
                self._send(encoder.heartbeat(time_ms))
                next_heartbeat += HEARTBEAT_PERIOD_S
            j += 1
            self.ticks = j
        self.state = "stopped"


class VirtualSerialCart(SerialCart):
    """``--plant virtual``: a :class:`VirtualCart` in this process, driven through the serial path.

    The cart boots once :meth:`connect` has opened the port, and is switched off on
    :meth:`close`, after it has taken the host's drive = 0 frames (so a test can check what it
    was left applying).
    """

    reports_true_speed = True
    """The simulator behind the line knows the true speeds: the trace gets them too."""

    def __init__(self, cart: VirtualCart, **kwargs: Any) -> None:
        super().__init__(cart.port, **kwargs)
        self.cart = cart

    def _port_opened(self) -> None:
        """Boot the cart once the port is open (opening a real cart's port resets it, too)."""
        if self.cart.state == "idle":
            self.cart.start()

    def _with_true_speed(self, measured: Measurement) -> Measurement:
        """The measurement with the simulator's true speeds at the same cart tick (rad/s)."""
        assert self.sample is not None
        true_a, true_b = self.cart.true_speeds.get(self.sample.cart_tick, (math.nan, math.nan))
        return Measurement(measured.speed_a_rad_s, measured.speed_b_rad_s, true_a, true_b)

    def reset(self) -> Measurement:
        """As :meth:`SerialCart.reset`, with the true speed: the simulator knows it."""
        return self._with_true_speed(super().reset())

    def receive(self) -> Measurement:
        """As :meth:`SerialCart.receive`, with the true speed: the simulator knows it."""
        return self._with_true_speed(super().receive())

    def close(self) -> None:
        was_connected = self.connected and not self.link.failure
        super().close()
        if was_connected:  # let the stop frames cross the line and reach control()
            deadline = time.perf_counter() + 0.2
            while self.cart.firmware.in_ints[1] != 0 and time.perf_counter() < deadline:
                time.sleep(0.005)
            self.cart.wait_ticks(2)
        self.cart.stop()
