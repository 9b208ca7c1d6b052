"""The bridge sketch's channel map (docs/serial-protocol.md §3) and the echo delays: the ticks
from a measurement to the echo of the command that answered it (:class:`EchoDelays`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import astuple, dataclass
from typing import Any

from cartctl.link.dialect import Gpio, check_gpio_counts

SEQ_MODULO = 32768  # host sequence numbers and cart ticks wrap here (int16 on the cart)
HOST_LOSS_WARN_PERCENT = 1.0  # more host frames (%) lost on the way to the cart: a warning
SEQ_WINDOW = 256  # a host sequence number further off (or behind) is a new host, not losses
WATCHDOG_MS = 70
"""The cart trips at the first ``control()`` this long (ms) after the last new host sequence
number: the motors are off at most 90 ms after the host's last frame (the next tick, then io())."""
BRIDGE_VERSION = 2
"""The bridge sketch's version, sent in float channel :data:`CH_BRIDGE_VERSION` (0 before 2)."""
BRIDGE_BAUD = 500_000  # bridge version 2's line (8N1): a 60-byte GPIO frame takes 1.2 ms
LEGACY_BAUD = 115_200  # the line of the course's firmware and of bridges before version 2
TIMING_FIRST_ID = 200
"""The bridge's THREAD_INFO reports after each GPIO have ids 200 onwards, the figure in the
duration field: the 10 ms thread's drain + io() + control() (µs), the longest 1 ms drain since the
previous tick (µs), the time since the previous tick started (µs), the most bytes a drain found
in the receive ring since the previous tick; :data:`TIMING_REPORTS` names their run maxima."""
TIMING_REPORTS = ("tick_busy_us_max", "drain_us_max", "tick_interval_us_max",
                  "rx_ring_high_water_bytes")  # fmt: skip
STATUS_DRIVING = 1  # status bit: the cart applies the requested voltages
STATUS_WATCHDOG = 2  # status bit: the watchdog has tripped, the cart applies zero volts

# the channel map: PC → cart floats (voltage A, voltage B (V), 0...) and ints (sequence number,
# drive, 0, 0); cart → PC the channels below, in the order of CartSample's fields (rad/s, V, rad;
# the labels of a monitor trace). The cart's helpers are int16: counters modulo 32768.
SAMPLE_FLOATS = ("speed_a", "speed_b", "voltage_a", "voltage_b", "position_a_rad",
                 "position_b_rad", "bridge_version")  # fmt: skip
SAMPLE_INTS = ("echo_seq", "cart_tick", "status", "host_frames_lost")
CH_BRIDGE_VERSION = SAMPLE_FLOATS.index("bridge_version")


def _version(value: float) -> int:
    """A version number from its float channel (0 for anything that is not a small whole number)."""
    return int(value) if 0.0 <= value < 1000.0 and float(value).is_integer() else 0


def next_seq(seq: int) -> int:
    """The host sequence number after ``seq`` (wraps at :data:`SEQ_MODULO`)."""
    return (seq + 1) % SEQ_MODULO


def tick_difference(earlier: int, later: int) -> int:
    """Ticks (or sequence steps) from ``earlier`` to ``later``, across the wrap, in 0..32767."""
    return (later - earlier) % SEQ_MODULO


@dataclass(frozen=True)
class HostCommand:
    """One PC → cart command frame: voltages (V), sequence number 0..32767, drive or stop."""

    voltage_a_v: float
    voltage_b_v: float
    seq: int
    drive: bool

    def to_channels(self) -> tuple[tuple[float, ...], tuple[int, ...]]:
        """The 8 floats and 4 ints of the GPIO frame."""
        floats = (float(self.voltage_a_v), float(self.voltage_b_v), *[0.0] * 6)
        return floats, (self.seq, int(self.drive), 0, 0)

    @classmethod
    def from_channels(cls, floats: Sequence[float], ints: Sequence[int]) -> HostCommand:
        """The command carried by a GPIO frame's channels (drive only if int 1 is exactly 1)."""
        check_gpio_counts(floats, ints)
        return cls(float(floats[0]), float(floats[1]), int(ints[0]), ints[1] == 1)


@dataclass(frozen=True)
class CartSample:
    """One cart → PC measurement frame (one 10 ms tick of the cart), in the channel map's units:
    ``echo_seq`` is the host sequence number of the command applied at this tick,
    ``host_frames_lost`` those skipped since boot (modulo 32768; 0 from an older bridge)."""

    time_ms: int
    speed_a_rad_s: float
    speed_b_rad_s: float
    applied_a_v: float
    applied_b_v: float
    position_a_rad: float
    position_b_rad: float
    echo_seq: int
    cart_tick: int
    driving: bool
    watchdog_tripped: bool
    host_frames_lost: int = 0
    bridge_version: int = 0

    @property
    def status(self) -> int:
        """The status bits as sent in int channel 2."""
        return STATUS_DRIVING * self.driving | STATUS_WATCHDOG * self.watchdog_tripped

    def to_channels(self) -> tuple[tuple[float, ...], tuple[int, ...]]:
        """The 8 floats and 4 ints of the GPIO frame."""
        floats = (*astuple(self)[1:7], self.bridge_version, 0.0)  # the fields' order, as sent
        ints = (self.echo_seq, self.cart_tick, self.status, self.host_frames_lost)
        return tuple(float(v) for v in floats), ints

    @classmethod
    def from_gpio(cls, gpio: Gpio) -> CartSample:
        """The sample carried by a GPIO message from the cart."""
        floats, ints = gpio.floats, gpio.ints
        check_gpio_counts(floats, ints)
        speed_a, speed_b, applied_a, applied_b, position_a, position_b, version, _ = floats
        measured = (speed_a, speed_b, applied_a, applied_b, position_a, position_b)
        echo, tick, status, lost = ints
        driving, tripped = bool(status & STATUS_DRIVING), bool(status & STATUS_WATCHDOG)
        lost %= SEQ_MODULO
        return cls(gpio.time_ms, *measured, echo, tick, driving, tripped, lost, _version(version))


MIN_ECHOES = 20  # echoes a measurement needs before it can be clear
CLEAR_SHARE = 0.85  # share of the echoes at one delay for a clear measurement (17 of 20)
CHANGE_SHARE = 0.05  # in a run, more echoes than this at another delay than the probe's


def _ticks(n: int) -> str:
    return f"{n} tick" + ("" if n == 1 else "s")


@dataclass(frozen=True)
class EchoDelays:
    """Echo delays counted per value: ``(delay_ticks, echoes)`` pairs by delay, echoes > 0."""

    counts: tuple[tuple[int, int], ...]

    @classmethod
    def of(cls, counts: Mapping[int, int]) -> EchoDelays:
        """From a mapping delay (ticks) → echoes (a :class:`collections.Counter`)."""
        return cls(tuple(sorted((int(d), int(n)) for d, n in counts.items() if n > 0)))

    @property
    def echoes(self) -> int:
        return sum(n for _, n in self.counts)

    @property
    def mode(self) -> int | None:
        """The most frequent delay (ticks; the shorter one on a tie), None without echoes."""
        return max(self.counts, key=lambda pair: (pair[1], -pair[0]), default=(None,))[0]

    def share(self, delay_ticks: int) -> float:
        """Share of the echoes at ``delay_ticks`` (0 without echoes)."""
        return dict(self.counts).get(delay_ticks, 0) / self.echoes if self.counts else 0.0

    @property
    def mode_share(self) -> float:
        """Share of the echoes at :attr:`mode` (0 without echoes)."""
        return 0.0 if self.mode is None else self.share(self.mode)

    @property
    def clear(self) -> bool:
        """At least :data:`MIN_ECHOES` echoes and :data:`CLEAR_SHARE` of them at one delay."""
        return self.echoes >= MIN_ECHOES and self.mode_share >= CLEAR_SHARE

    def describe(self) -> str:
        """``1 tick in 19 of 20 echoes (95 %), 2 ticks in 1``: the mode first, then the rest."""
        mode = self.mode
        if mode is None:
            return "no echoes"
        head = (
            f"{_ticks(mode)} in {dict(self.counts)[mode]} of {self.echoes} echoes "
            f"({100.0 * self.mode_share:.0f} %)"
        )
        return ", ".join([head, *(f"{_ticks(d)} in {n}" for d, n in self.counts if d != mode)])

    def to_dict(self) -> dict[str, Any]:
        """For ``--json``: mode, echoes, the mode's share, range, clear, counts by delay."""
        return {
            "ticks": self.mode,
            "echoes": self.echoes,
            "mode_share_percent": 100.0 * self.mode_share,
            "min": self.counts[0][0] if self.counts else None,
            "max": self.counts[-1][0] if self.counts else None,
            "clear": self.clear,
            "counts": {str(d): n for d, n in self.counts},
        }


def delay_change(probe: EchoDelays, run: EchoDelays) -> str | None:
    """How the run's echo delays differ from the probe's before it; None when they agree.

    A change is another most frequent delay than the probe's, or more than
    :data:`CHANGE_SHARE` of the run's echoes at another delay than the probe's most frequent.
    """
    expected = probe.mode
    if expected is None or run.mode is None:
        return None
    other = 1.0 - run.share(expected)
    if run.mode == expected and other <= CHANGE_SHARE:
        return None
    what = (
        "changed"
        if run.mode != expected
        else f"varied ({100.0 * other:.0f} % of the commands took another than {_ticks(expected)})"
    )
    return (
        f"the loop delay {what} during the run: {run.describe()}; the probe before it measured "
        f"{probe.describe()}"
    )
