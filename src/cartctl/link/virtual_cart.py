"""The virtual cart: the physics simulator behind a pseudo-terminal, speaking as the bridge does
(docs/serial-protocol.md §8). Its drains run on the cart's clock (tick k starts ``k × 10 ms``
after boot): a busy host delays the replies, not when bytes arrived.
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import random
import termios
import threading
import time
import tty
from collections.abc import Callable
from typing import Any

import cartctl.link.cart_uart as uart
from cartctl.cart import PERIOD_S
from cartctl.errors import InputError
from cartctl.link.bridge import (
    BRIDGE_BAUD,
    CH_BRIDGE_VERSION,
    LEGACY_BAUD,
    TIMING_FIRST_ID,
    tick_difference,
)
from cartctl.link.cart_faults import RECEIVE_SCHEDULES, CartFaults
from cartctl.link.dialect import Encoder, encode_gpiox_v2
from cartctl.link.firmware import BridgeFirmware, CartIO, OnboardFirmware
from cartctl.link.serial_cart import SerialCart
from cartctl.plants.base import Measurement
from cartctl.plants.physics import PhysicsPlant
from cartctl.stopping import held

HEARTBEAT_PERIOD_S = 1.1
SILENCE_TIMEOUT_S = 0.5
"""A host in this process calls the virtual cart silent after this long (a real cart's: 0.1 s):
the cart is threads of this process, which a busy PC can hold up for longer. Its stall and pull
faults are still found, that much later."""
COMM_PHASE_US = 1200  # the cart's GPIO goes out this long into the tick (io(), control())
DRAIN_BUSY_US = 60  # reported as THREAD_INFO 201 (200: COMM_PHASE_US); there is no AVR to time
_TERMIOS_SPEED = {getattr(termios, n): int(n[1:]) for n in dir(termios) if n[1:].isdigit()}


def _wait_until(ready: Callable[[], bool], timeout_s: float, poll_s: float) -> None:
    deadline = time.perf_counter() + timeout_s
    while not ready() and time.perf_counter() < deadline:
        time.sleep(poll_s)


class VirtualCart:
    """The physical simulator behind a pseudo-terminal (:attr:`port`, ``/dev/pts/N``).

    ``preset`` and ``noise_std_rad_s`` (rad/s) go to the simulator, ``seed`` seeds it and the
    faults; ``firmware`` runs in ``control()``: the bridge sketch, or a controller on the cart
    (``receive=microos``). Use as a context manager, or :meth:`start` and :meth:`stop`.
    """

    def __init__(
        self,
        preset: str = "ground",
        *,
        noise_std_rad_s: float = 0.0,
        seed: int | None = None,
        faults: CartFaults | None = None,
        firmware: OnboardFirmware | None = None,
    ) -> None:
        self.faults = faults or CartFaults()
        if firmware is not None and self.faults.bridge != 2:
            raise InputError(
                "bridge=1 sets up the bridge sketch; an on-board controller runs without it"
            )
        self.physics = PhysicsPlant(
            preset,
            noise_std_rad_s=noise_std_rad_s,
            seed=seed,
            actuation_ms=self.faults.actuation_ms,
            reversed_motors=self.faults.reversed_motors,
        )
        self.period_s = PERIOD_S
        self.firmware = firmware or BridgeFirmware()
        self.receive_schedule = self.faults.receive if firmware is None else "microos"
        self.bridge_version = self.faults.bridge if firmware is None else 0  # 0: not the bridge
        if self.receive_schedule == "microos" and self.bridge_version == 2:
            self.bridge_version = 1  # microOS's thread alone: the sketch before its own drains
        bridge2 = self.bridge_version == 2
        self.baud = BRIDGE_BAUD if bridge2 else LEGACY_BAUD
        self.ring_bytes = uart.BRIDGE_RX_RING_BYTES if bridge2 else uart.RX_RING_BYTES
        self._rng = random.Random(seed)
        usb = None
        if self.faults.usb:  # the phases of the 16U2's flush timer and the PC's USB frames
            flush_phase_s = self._rng.uniform(0.0, uart.USB_FLUSH_PERIOD_S)
            usb = uart.UsbBridge(flush_phase_s, self._rng.uniform(0.0, uart.USB_FRAME_S))
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing before the host configures the port
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._fds_lock = threading.Lock()  # the ticker (a pulled cable) and stop() may both close
        byte_s = uart.byte_time_s(self.baud)
        self._writer = uart.PacedWriter(self._master, self._stop, byte_s, usb)
        jitter_s = self.faults.reply_jitter_ms / 1000.0
        rng_seed = None if seed is None else seed + 1
        self._reader = uart.LineReader(self._master, self._stop, byte_s, usb, jitter_s, rng_seed)
        self._reader.rate_ok = self._writer.rate_ok = self._host_rate_matches
        self._parser = uart.MicroosParser()
        self._ring_high = self._lag_us = 0
        self._held: tuple[list[float], list[int]] = ([0.0] * 8, [0] * 4)
        self.boot_s = 0.0  # time.perf_counter at boot: tick k starts k × period_s later
        self._ticker = threading.Thread(
            target=self._tick_until_stopped, name="virtual-cart", daemon=True
        )
        self._ended = threading.Event()  # set as the ticker ends (see stop)
        self.ticks = 0
        self.true_speeds: dict[int, tuple[float, float]] = {}  # rad/s, by the cart's tick counter
        self.frames_received = 0  # GPIO frames microOS decoded from the host
        self.ring_dropped_bytes = 0
        self.last_voltage_v: tuple[float, float] = (0.0, 0.0)
        # (time.perf_counter, A, B): the voltages io() put on the motors at recent ticks
        self.applied_log = collections.deque[tuple[float, float, float]](maxlen=1024)
        self.state = "idle"
        self.first_frame_at_s: float | None = None  # the host's first GPIO: faults count from it
        self.fault_at_s: float | None = None  # when the injected stall or pulled cable began

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
        # the ticker's own event, not join(): on Python 3.11 a Ctrl-C inside join() can mark a
        # running thread as stopped, and the pseudo-terminal would close under it
        if self._ticker.ident is not None and self._ticker is not threading.current_thread():
            self._ended.wait(timeout=1.0)
        self._cut_line()

    def _cut_line(self) -> None:
        """Close the pseudo-terminal once the writer and reader have seen the stop (a thread still
        at it could read or write a closed descriptor's number, or one reused since)."""
        for thread in (self._writer, self._reader):
            if thread.is_alive() and thread is not threading.current_thread():
                thread.join(timeout=1.0)
        self._close_fds()

    def wait(self, seconds: float | None = None) -> None:
        """Block until the cart stops (Ctrl-C, a pulled cable), or for at most ``seconds``."""
        self._ticker.join(timeout=seconds)

    def arm_faults(self) -> None:
        """Start the stall/pull clock now, for a host that never sends (``cartctl monitor``)."""
        if self.first_frame_at_s is None:
            self.first_frame_at_s = time.perf_counter()

    @property
    def last_host_byte_at_s(self) -> float | None:  # time.perf_counter; None: none yet
        return self._reader.last_byte_at_s

    def wait_ticks(self, n: int, timeout_s: float = 0.5) -> None:
        """Block until the cart has run ``n`` more ticks (or stopped, or ``timeout_s`` passed)."""
        target = self.ticks + n
        _wait_until(lambda: self.ticks >= target or not self._ticker.is_alive(), timeout_s, 0.002)

    def _close_fds(self) -> None:
        with self._fds_lock:  # each descriptor closed once, never a number reused since
            fds, self._master, self._slave = (self._master, self._slave), -1, -1
        for fd in fds:
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)

    def _send(self, frame: bytes, not_before_s: float, *, track: bool = False) -> None:
        faults, rng = self.faults, self._rng
        if faults.garbage and rng.random() < faults.garbage:
            burst = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 16)))
            self._writer.put(burst, not_before_s)
        if faults.corrupt and rng.random() < faults.corrupt:
            data = bytearray(frame)
            i = rng.randrange(1, len(data))  # any byte after the start byte
            data[i] ^= rng.randint(1, 255)
            frame = bytes(data)
        self._writer.put(frame, not_before_s, track=track)

    def _drain(self, at_us: int, hand_over: bool) -> None:
        """A call of microOS's receive at ``at_us`` after boot; ``hand_over``: the bridge's."""
        until_us = at_us - self._lag_us  # ``late``: what reached the line a tick ago
        arrived = self._reader.take(self.boot_s + until_us * 1e-6)
        kept, dropped = uart.fill_ring(arrived, self.ring_bytes)
        self._ring_high = max(self._ring_high, len(kept))
        self.ring_dropped_bytes += dropped
        for gpio in self._parser.feed(kept):
            self._held = (list(gpio.floats), list(gpio.ints))
            self.frames_received += 1
            if self.first_frame_at_s is None:
                self.first_frame_at_s = self.boot_s + at_us * 1e-6
        if hand_over:
            self.firmware.receive(*self._held, at_us // 1000)

    def receive_for_tick(self, j: int) -> None:
        """Every drain from the previous tick's ``io()`` up to tick ``j``'s, in order: bridge 2
        every 1 ms and right before ``io()``; bridge 1 also microOS's communication thread
        :data:`COMM_PHASE_US` into each tick; ``receive='microos'`` that thread alone."""
        period_us = round(self.period_s * 1e6)
        tick_us = j * period_us
        self._lag_us = period_us if self.faults.late_at(j) else 0
        drain_us = RECEIVE_SCHEDULES[self.receive_schedule]
        if j > 0:
            start_us = tick_us - period_us
            drains = [] if self.bridge_version == 2 else [(start_us + COMM_PHASE_US, False)]
            if drain_us is not None:  # its drain at start_us came before that tick's io()
                drains += [(start_us + m * drain_us, True) for m in range(1, period_us // drain_us)]
            for at_us, hand_over in sorted(drains):
                self._drain(at_us, hand_over)
        if drain_us is not None:
            self._drain(tick_us, hand_over=True)
        else:
            self.firmware.receive(*self._held, tick_us // 1000)

    def _host_rate_matches(self) -> bool:
        """Whether the host opened the port at the cart's rate (else both sides read noise)."""
        try:
            speed = termios.tcgetattr(self._slave)[5]
        except (OSError, ValueError, termios.error):  # ValueError: closed (-1)
            return True
        rate = _TERMIOS_SPEED.get(speed)
        return rate is None or rate == self.baud

    def _tick_until_stopped(self) -> None:
        try:
            self._run()
        finally:
            self._ended.set()

    def _run(self) -> None:
        encoder, physics, firmware, faults = Encoder(), self.physics, self.firmware, self.faults
        rad_per_count = 2.0 * math.pi / physics.params.counts_per_rev
        period_us = round(self.period_s * 1e6)
        boot = self.boot_s = time.perf_counter()
        self.state = "running"
        generation_a = faults.generation == "a"
        if generation_a:  # a generation-B cart speaks MAVLink 2 only (its GPIOX frames, below)
            for frame in [encoder.heartbeat(0), *encoder.print_text(firmware.ready_text + "\r\n")]:
                self._writer.put(frame)
        next_heartbeat = boot + HEARTBEAT_PERIOD_S
        measurement = physics.reset()
        voltage = (0.0, 0.0)
        j = 0
        while not self._stop.is_set():
            tick_us = j * period_us
            deadline = boot + tick_us * 1e-6
            time.sleep(max(0.0, deadline - time.perf_counter()))
            now = time.perf_counter()
            driven = 0.0 if self.first_frame_at_s is None else now - self.first_frame_at_s
            if faults.pull_after_s is not None and driven >= faults.pull_after_s:
                self.state, self.fault_at_s = "cable pulled", time.perf_counter()
                self._stop.set()
                self._cut_line()
                return
            if faults.stall_after_s is not None and driven >= faults.stall_after_s:
                self.state, self.fault_at_s = "stalled", time.perf_counter()
                self._stop.wait()
                return
            self.receive_for_tick(j)  # on the cart's clock, whenever this thread gets here
            if isinstance(firmware, BridgeFirmware) and self.bridge_version == 2:
                voltage = firmware.command_v  # the newest command the drains stored
            # io(): the stored voltage drives from actuation_ms after the previous tick; encoders
            if j > 0:
                measurement = physics.step(*voltage)
            applied = physics.applied_voltage_v
            self.applied_log.append((deadline, *applied))
            positions = (count * rad_per_count for count in physics.encoder_counts)
            io = CartIO(measurement.speed_a_rad_s, measurement.speed_b_rad_s, *applied, *positions)
            true_speeds = (measurement.true_speed_a_rad_s, measurement.true_speed_b_rad_s)
            self.true_speeds[firmware.tick] = (true_speeds[0] or 0.0, true_speeds[1] or 0.0)
            self.true_speeds.pop(tick_difference(512, firmware.tick), None)  # keep the recent ones
            voltage = firmware.control(io, tick_us // 1000)
            if self.bridge_version == 1:  # the sketch before version 2 sends 0 there
                firmware.out_floats[CH_BRIDGE_VERSION] = 0.0
            self.last_voltage_v = voltage
            # microOS's communication thread sends what control() wrote
            send_at = deadline + COMM_PHASE_US * 1e-6
            time_ms = (tick_us // 1000) & 0xFFFFFFFF
            if not generation_a:
                floats12 = [*firmware.out_floats, *(float(v) for v in firmware.out_ints)]
                self._send(encode_gpiox_v2(time_ms, floats12, seq=j % 256), send_at)
            else:
                frame = encoder.gpio(time_ms, firmware.out_floats, firmware.out_ints)
                self._send(frame, send_at, track=True)
                if self.bridge_version == 2:  # its tick's timing: 120 bytes, a USB flush at once
                    reports = (COMM_PHASE_US, DRAIN_BUSY_US, period_us, self._ring_high)
                    self._ring_high = 0
                    for thread, value in enumerate(reports, TIMING_FIRST_ID):
                        report = encoder.thread_info(time_ms, thread, value, executions=j + 1)
                        self._writer.put(report, send_at)
            if generation_a and now >= next_heartbeat:
                self._send(encoder.heartbeat(time_ms), send_at)
                next_heartbeat += HEARTBEAT_PERIOD_S
            self.ticks = j = j + 1
        self.state = "stopped"


class VirtualSerialCart(SerialCart):
    """``--plant virtual``: :class:`~cartctl.link.serial_cart.SerialCart` on a :class:`VirtualCart`
    of this process, plus the true speed at each cart tick. The cart boots once :meth:`connect`
    has opened the port, and is switched off on :meth:`close`, after the drive = 0 frames."""

    reports_true_speed = True

    def __init__(self, cart: VirtualCart, **kwargs: Any) -> None:
        kwargs.setdefault("silence_timeout_s", SILENCE_TIMEOUT_S)
        super().__init__(cart.port, **kwargs)
        self.cart = cart

    def _port_opened(self) -> None:
        if self.cart.state == "idle":  # opening a real cart's port resets it, too
            self.cart.start()

    def _measured(self) -> Measurement:
        assert self.sample is not None
        true_a, true_b = self.cart.true_speeds.get(self.sample.cart_tick, (math.nan, math.nan))
        return Measurement(self.sample.speed_a_rad_s, self.sample.speed_b_rad_s, true_a, true_b)

    def close(self) -> None:
        with held():  # a stop signal meanwhile: raised once the cart is off (SerialCart.close)
            try:
                was_connected = self.connected and not self.link.failure
                super().close()
                if was_connected:  # let the stop frames cross the line and reach control()
                    _wait_until(lambda: self.cart.firmware.in_ints[1] == 0, 0.2, 0.005)
                    self.cart.wait_ticks(2)
            finally:
                self.cart.stop()
