"""The real cart over serial (``--plant serial:PORT``), running the bridge sketch of ``firmware/``:
the cart clocks the loop, and the echo of each command gives the loop delay E
(docs/serial-protocol.md §4.3, §7; a model has ``nk = E + 1``).
"""

from __future__ import annotations

import collections
import contextlib
import statistics
import sys
import time
from typing import Any

import numpy as np

import cartctl.link.bridge as bridge
from cartctl.cart import PERIOD_S
from cartctl.choices import DEFAULT_CONNECT_TIMEOUT_S
from cartctl.errors import PlantError
from cartctl.link.cart_link import CartLink, UnsupportedCartError
from cartctl.link.dialect import Encoder, Gpio
from cartctl.measures.metrics import percentiles
from cartctl.plants.base import Measurement
from cartctl.stopping import held

STOP_FRAMES = 3  # drive = 0 frames sent on close (one may be lost to line noise)
PROBE_ECHOES = bridge.MIN_ECHOES  # echoes measure_loop_delay judges first: done when clear
UNDRIVEN_SILENCE_S = 0.5
"""Longest wait for a GPIO while nothing is driven (s: the first tick, the probe): a host held up
that long (a loaded PC) is no fault of the cart's."""
BACKLOG_WAIT_S = 0.006
"""A GPIO that follows the one :meth:`SerialCart.reset` took within this long is a backlog (the
cart's frames come 10 ms apart, give or take the USB bridge's 5 ms), not the next tick."""
FLASH_HINT = (
    f"flash firmware/cartctl_bridge (bridge version {bridge.BRIDGE_VERSION}, 500 kbaud; see "
    "firmware/README.md)"
)


class SerialCart:
    """A cart on a serial port as a :class:`~cartctl.plants.base.Plant`, clocked by the cart.

    ``connect_timeout_s`` bounds the wait for the first HEARTBEAT; the rest goes to the
    :class:`~cartctl.link.cart_link.CartLink` (``silence_timeout_s``, ``on_print``, ...).
    :meth:`send` and :meth:`receive` split :meth:`step` (the cart-clocked loop times its compute
    between).
    """

    period_s: float = PERIOD_S

    def __init__(
        self,
        port: str,
        *,
        connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
        **link_options: Any,
    ) -> None:
        self.port = port
        self.connect_timeout_s = float(connect_timeout_s)
        self.link = CartLink(port, **link_options)
        self.encoder = Encoder()
        self.connected = False
        self.sample: bridge.CartSample | None = None
        self.arrival_s = 0.0
        self.tick_index = 0
        self._seq = 1
        self._sent_at: dict[int, int] = {}
        self._echo = -1
        # echoes per delay (ticks) since the probe, and what measure_loop_delay measured
        self.echo_delays: collections.Counter[int] = collections.Counter()
        self.probe_delays: bridge.EchoDelays | None = None
        self.missed_ticks = self.skipped_ticks = self.watchdog_trips = 0
        self.frames_sent = 0  # since the last reset (the stop frames of close excluded)
        self._lost_base = 0
        self._sent_any = False
        # per tick of the run: from the cart's frame decoded to the host's reply written (s)
        self.reply_latency_s = collections.deque[float](maxlen=1 << 20)

    def connect(self) -> None:
        """Open the port and wait for the cart's HEARTBEAT (raises a clear error otherwise)."""
        if self.connected:
            return
        self.link.open()
        self._port_opened()
        baud = self.link.wait_heartbeat_any_rate(self.connect_timeout_s)
        if baud != bridge.BRIDGE_BAUD:
            self.link.close()
            raise UnsupportedCartError(
                f"the cart on {self.port} answers at {baud} baud: it runs the course's "
                f"firmware or a cartctl bridge older than version {bridge.BRIDGE_VERSION}; "
                f"{FLASH_HINT}"
            )
        self.connected = True

    def _port_opened(self) -> None:  # before the HEARTBEAT is waited for (a virtual cart boots)
        pass

    def reset(self) -> Measurement:
        """Connect if needed, drop what waited in the buffer, and take the next GPIO as tick 0."""
        self.connect()
        while self.link.gpio_waiting():  # stale ticks from before the run
            self.link.next_gpio()
        undriven_s = max(self.link.silence_timeout_s, UNDRIVEN_SILENCE_S)
        self.link.next_gpio(undriven_s)
        # a backlog still coming in is not a fresh tick: answering it would put two replies into
        # one cart tick and lose one. Tick 0 is the next frame, answered while it is fresh.
        while self.link.gpio_waiting(wait_s=BACKLOG_WAIT_S):
            self.link.next_gpio()
        gpio, arrival = self.link.next_gpio(undriven_s)
        sample = bridge.CartSample.from_gpio(gpio)
        if sample.bridge_version != bridge.BRIDGE_VERSION:
            raise UnsupportedCartError(
                f"the cart on {self.port} runs bridge version {sample.bridge_version or 'before 2'}"
                f", cartctl needs {bridge.BRIDGE_VERSION}; {FLASH_HINT}"
            )
        self.sample, self.arrival_s, self.tick_index = sample, arrival, 0
        if not self._sent_any:  # differs from what the cart holds: counts as new, none lost
            self._seq = bridge.next_seq(sample.echo_seq)
        self._echo = sample.echo_seq
        self._sent_at.clear()
        self._lost_base = sample.host_frames_lost
        self.frames_sent = 0
        self.reply_latency_s.clear()
        self.link.thread_maxima.clear()
        return self._measured()

    def send(self, voltage_a_v: float, voltage_b_v: float, *, drive: bool = True) -> None:
        """Send the channel vector for this tick (voltages, sequence number, drive)."""
        self._send(voltage_a_v, voltage_b_v, drive)
        self.frames_sent += 1
        self.reply_latency_s.append(time.perf_counter() - self.arrival_s)

    def _send(self, voltage_a_v: float, voltage_b_v: float, drive: bool) -> None:
        if self.link.vanished:
            raise PlantError(self.link.failure)
        command = bridge.HostCommand(float(voltage_a_v), float(voltage_b_v), self._seq, drive)
        floats, ints = command.to_channels()
        self.link.send(self.encoder.gpio(0, floats, ints))
        self._sent_any = True
        self._sent_at[self._seq] = self.tick_index
        if len(self._sent_at) > 256:  # only the recent ones can still be echoed
            self._sent_at.pop(next(iter(self._sent_at)))
        self._seq = bridge.next_seq(self._seq)

    def receive(self) -> Measurement:
        """Wait for the cart's next tick and return its measurement; when the host has fallen
        behind, older GPIOs waiting are dropped (``skipped_ticks``): the freshest is answered."""
        if self.link.failure:  # after a fault, do not wait again (zero volts go out at once)
            raise PlantError(self.link.failure)
        self._accept(*self.link.next_gpio())
        while self.link.gpio_waiting():
            self._accept(*self.link.next_gpio())
            self.skipped_ticks += 1
        return self._measured()

    def _measured(self) -> Measurement:
        assert self.sample is not None
        return Measurement(self.sample.speed_a_rad_s, self.sample.speed_b_rad_s)

    def _accept(self, gpio: Gpio, arrival_s: float) -> None:
        """Count missing cart ticks, watchdog trips and the echo delay of one GPIO."""
        sample = bridge.CartSample.from_gpio(gpio)
        previous = self.sample
        if previous is not None:
            gap = bridge.tick_difference(previous.cart_tick, sample.cart_tick)
            self.missed_ticks += max(0, gap - 1)
            self.tick_index += max(1, gap)
            if sample.watchdog_tripped and not previous.watchdog_tripped:
                self.watchdog_trips += 1
        if sample.echo_seq != self._echo:
            self._echo = sample.echo_seq
            if (sent := self._sent_at.get(sample.echo_seq)) is not None:
                self.echo_delays[self.tick_index - sent] += 1
        self.sample, self.arrival_s = sample, arrival_s

    def measure_loop_delay(
        self, *, echoes: int = PROBE_ECHOES, max_echoes: int = 50, max_ticks: int = 100
    ) -> int:
        """The loop delay (ticks), measured from the echo with drive = 0 (echoed all the same):
        the most frequent delay of ``echoes`` echoes, or of ``max_echoes`` when those are not clear
        (:class:`~cartctl.link.bridge.EchoDelays`); :attr:`probe_delays` keeps the spread. No echo
        within ``max_ticks`` ticks raises :class:`~cartctl.errors.PlantError`."""
        self.reset()
        self.echo_delays.clear()
        judged = False
        silence_s, switch_s = self.link.silence_timeout_s, sys.getswitchinterval()
        self.link.silence_timeout_s = max(silence_s, UNDRIVEN_SILENCE_S)
        sys.setswitchinterval(min(switch_s, 1e-4))  # as in the loop it judges (run, excite)
        try:
            for _ in range(max_ticks):
                self.send(0.0, 0.0, drive=False)
                self.receive()
                total = self.echo_delays.total()
                if total >= max_echoes:
                    break
                if total >= echoes and not judged:  # judged once: no stopping at a lucky moment
                    judged = True
                    if bridge.EchoDelays.of(self.echo_delays).clear:
                        break
        finally:
            self.link.silence_timeout_s = silence_s
            sys.setswitchinterval(switch_s)
        self.probe_delays = bridge.EchoDelays.of(self.echo_delays)
        delay = self.loop_delay_ticks
        if delay is None:
            raise PlantError(
                f"the cart on {self.port} echoed none of {max_ticks} commands: is the bridge "
                "sketch of firmware/ on it?"
            )
        self.echo_delays.clear()
        self.missed_ticks = self.skipped_ticks = self.watchdog_trips = 0
        return delay

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        """Send this tick's voltages, then wait for the cart's next tick."""
        self.send(voltage_a_v, voltage_b_v)
        return self.receive()

    def close(self) -> None:
        """Send drive = 0 with zero volts (if the port still works), then close it. A stop signal
        meanwhile waits until the port is closed (:class:`cartctl.stopping.held`); a Ctrl-C where
        that is not installed still closes it."""
        with held():
            try:
                if self.connected and not self.link.vanished:
                    with contextlib.suppress(PlantError):
                        for _ in range(STOP_FRAMES):
                            self._send(0.0, 0.0, drive=False)
            finally:
                self.link.close()
                self.connected = False

    @property
    def loop_delay_ticks(self) -> int | None:
        """Ticks from a measurement to the tick its voltage is on the motor: the most frequent echo
        delay E (the shorter on a tie; the bridge echoes what ``io()`` applied); None before any."""
        return bridge.EchoDelays.of(self.echo_delays).mode

    echo_delay_ticks = loop_delay_ticks

    @property
    def host_frames_lost(self) -> int:
        """The host's frames the cart never saw since :meth:`reset`, by the cart's count (which
        misses the frames sent after the last sample's tick)."""
        if self.sample is None:
            return 0
        return bridge.tick_difference(self._lost_base, self.sample.host_frames_lost)

    def _cart_timing(self) -> dict[str, int] | None:
        """The maxima of the bridge's own reports over the run, None without any."""
        maxima = self.link.thread_maxima
        ids = range(bridge.TIMING_FIRST_ID, bridge.TIMING_FIRST_ID + len(bridge.TIMING_REPORTS))
        if maxima.keys().isdisjoint(ids):
            return None
        return {name: maxima.get(i, 0) for i, name in zip(ids, bridge.TIMING_REPORTS, strict=True)}

    def link_summary(self) -> dict[str, Any]:
        """Link figures for the run summary (``run --json``'s ``link``)."""
        stats, probe = self.link.stats, self.probe_delays
        seen = bridge.EchoDelays.of(self.echo_delays)
        delays = list(self.echo_delays.elements())
        lost, sent = self.host_frames_lost, self.frames_sent
        return {
            "loop_delay_ticks": self.loop_delay_ticks,
            "link": {
                "port": self.port,
                "echo_delay_ticks": self.echo_delay_ticks,
                "echo_delay_range": [min(delays), max(delays)] if delays else None,
                "echo_delay_median": statistics.median(delays) if delays else None,
                "loop_delay_ticks_seen": seen.to_dict()["counts"],
                "loop_delay_probe": None if probe is None else probe.to_dict(),
                "loop_delay_change": None if probe is None else bridge.delay_change(probe, seen),
                **{k: v for k, v in stats.to_dict().items() if k != "generation_b_frames"},
                "missed_ticks": self.missed_ticks,
                "skipped_ticks": self.skipped_ticks,
                "watchdog_trips": self.watchdog_trips,
                "host_frames_sent": sent,
                "host_frames_lost": lost,
                "host_frames_lost_percent": 100.0 * lost / sent if sent else 0.0,
                "reply_latency_us": percentiles(1e6 * np.array(self.reply_latency_s)),
                "cart_timing": self._cart_timing(),
            },
        }
