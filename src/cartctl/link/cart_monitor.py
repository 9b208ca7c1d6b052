"""Passive recording of what a cart sends (``cartctl monitor``): labelled GPIO rows, text, events.

A row is ``time_s, tick, <12 labels>``; ``time_s`` is k · Ts with the cart's tick k from the
frames' millisecond stamps, k = max(k_prev + 1, round(Δms / 10 ms)) (docs/serial.md).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from cartctl.cart import PERIOD_S
from cartctl.errors import InputError, PlantError
from cartctl.link.cart_link import CartLink
from cartctl.link.dialect import GPIO_FLOAT_COUNT, GPIO_INT_COUNT, Event, Gpio
from cartctl.link.firmware import CH_FIRMWARE_ID, CHANNEL_KEYS, Firmware, recognise_firmware
from cartctl.sinks.base import Sink

DEFAULT_LABELS: tuple[str, ...] = (
    *(f"FloatIn{i}" for i in range(GPIO_FLOAT_COUNT)),
    *(f"IntIn{i}" for i in range(GPIO_INT_COUNT)),
)
"""QRoboticsCenter's default labels, in :data:`CHANNEL_KEYS` order."""
TIME_COLUMN, TICK_COLUMN = "time_s", "tick"
PRINT_ENTITY, EVENT_ENTITY = "cart/print", "cart/events"
_LABEL = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_TIME_MODULO_MS = 1 << 32  # the GPIO's time field is a u32 of milliseconds
_PERIOD_MS = PERIOD_S * 1000.0
_TICKS_PER_S = round(1.0 / PERIOD_S)
RECOGNISE_FRAMES = 10
"""Frames (100 ms) that may go by without a firmware marker before the labels are chosen (a
firmware's first frames may go out before its first ``control()`` filled them)."""


def parse_labels(text: str | None) -> tuple[str, ...]:
    """The 12 channel labels, in :data:`CHANNEL_KEYS` order, from ``f0=speed_a,i0=echo,...``
    (channels not named keep :data:`DEFAULT_LABELS`); InputError on a bad or repeated item, or
    when two columns end up with one name."""
    labels = dict(zip(CHANNEL_KEYS, DEFAULT_LABELS, strict=True))
    given: set[str] = set()
    for item in filter(None, (part.strip() for part in (text or "").split(","))):
        key, sep, label = (s.strip() for s in item.partition("="))
        key = key.lower()
        if not sep or key not in labels:
            raise InputError(
                f"bad label '{item}'; expected KEY=LABEL with KEY f0..f7 (float channels) or "
                "i0..i3 (int channels)"
            )
        if key in given:
            raise InputError(f"channel {key} is labelled twice in '{text}'")
        if not _LABEL.match(label):
            raise InputError(
                f"label '{label}' of {key} must be an identifier (letters, digits and '_', "
                "not starting with a digit): it names a CSV column and a Rerun entity"
            )
        given.add(key)
        labels[key] = label
    seen: dict[str, str] = {TIME_COLUMN: "the time column", TICK_COLUMN: "the tick column"}
    for key, label in labels.items():
        if label in seen:
            raise InputError(f"label '{label}' of {key} is already used by {seen[label]}")
        seen[label] = f"channel {key}"
    return tuple(labels.values())


def firmware_labels(firmware: Firmware | None) -> tuple[str, ...]:
    """The 12 labels of a firmware's channels, QRoboticsCenter's for those it does not name."""
    labels = dict(zip(CHANNEL_KEYS, DEFAULT_LABELS, strict=True))
    return tuple({**labels, **dict(firmware.labels if firmware else ())}.values())


def describe_labels(
    firmware: Firmware | None, marker: float | None, labels: Sequence[str], *, given: bool
) -> str:
    """One line: the firmware (told by float 6 = ``marker``; None: no frame came) and the labels
    used (``given``: from ``--labels``)."""
    what = firmware.name if firmware is not None else "not one of cartctl's"
    told = "no frame came" if marker is None else f"by float {CH_FIRMWARE_ID} = {marker:g}"
    what = "unknown" if marker is None else what  # no frame: nothing is known of it
    named = ",".join(
        f"{key}={label}"
        for key, label, default in zip(CHANNEL_KEYS, labels, DEFAULT_LABELS, strict=True)
        if label != default
    )
    used = f"labels {'from --labels ' if given else ''}{named}, the others QRoboticsCenter's"
    if not named:
        used = "QRoboticsCenter's labels (FloatIn0..7, IntIn0..3)"
        used += "" if given else "; name the channels with --labels"
    return f"firmware: {what}, {told}; {used}"


class TextSink(Protocol):
    def log_text(self, entity: str, text: str, time_s: float, tick: int, level: str) -> None: ...


@dataclass
class MonitorResult:
    """What a monitor run saw (GPIO rows, cart time of the last, texts) and why it stopped
    (``stopped``: 'duration', 'interrupted' (Ctrl-C) or 'fault', with ``failure``)."""

    frames: int = 0
    duration_s: float = 0.0
    print_lines: int = 0
    events: int = 0
    stopped: str = "duration"
    failure: str | None = None


class Monitor:
    """Reads a connected link and writes one row per GPIO to the sinks (never sends anything).

    The channels are named by ``labels`` (:func:`parse_labels`), else by the firmware the first
    marked frame names, else QRoboticsCenter's; the row sinks open once they are chosen, and what
    was held until then is written in order. ``echo`` also receives each PRINT line, ``announce``
    the firmware told. The caller closes the sinks."""

    def __init__(
        self,
        rows: Sequence[Sink],
        texts: Sequence[TextSink],
        labels: Sequence[str] | None = None,
        *,
        echo: Callable[[str], None] | None = None,
        announce: Callable[[str], None] | None = None,
    ) -> None:
        self.rows, self.texts, self.echo, self.announce = list(rows), list(texts), echo, announce
        self.given_labels = None if labels is None else tuple(labels)
        self.labels: tuple[str, ...] | None = None
        self.firmware: Firmware | None = None  # what the frames named (None: not cartctl's)
        self.result = MonitorResult()
        self.stop_requested = False
        self._decided = False  # whether the frames were looked at for a firmware
        self._looked: list[Gpio] = []  # the frames looked at for a marker
        self._held: list[Callable[[], None]] = []  # rows and texts to write, in order
        self._last_ms: int | None = None  # the previous GPIO's stamp (ms)
        self._elapsed_ms = 0  # the stamps' distance from the first GPIO's (ms)
        self._cart_tick = -1  # the cart's tick of the last row, since the first GPIO

    def on_print(self, line: str) -> None:  # CartLink's PRINT callback
        self.result.print_lines += 1
        if self.echo is not None:
            self.echo(line)
        self._hold(lambda: self._log(PRINT_ENTITY, line))

    def on_event(self, event: Event) -> None:  # CartLink's EVENT callback
        self.result.events += 1
        button = event.button
        text = f"button {button} pressed" if button is not None else f"event {event.type}"
        self._hold(lambda: self._log(EVENT_ENTITY, text))

    def open(self, labels: tuple[str, ...] = DEFAULT_LABELS) -> None:
        """Open the row sinks with the labels given, else ``labels``. Once only; the labels are
        then fixed."""
        if self.labels is not None:
            return
        self.labels = self.given_labels or labels
        for sink in self.rows:
            sink.open((TIME_COLUMN, TICK_COLUMN, *self.labels))

    def run(self, link: CartLink, duration_s: float | None = None) -> MonitorResult:
        """Record until ``duration_s`` of cart time (S / 0.01 rows), a line fault (PlantError:
        ``stopped = 'fault'``), :attr:`stop_requested` (set from a signal handler) or Ctrl-C
        (``'interrupted'``); nothing is raised. The sinks are then open and hold every frame kept.
        """
        result = self.result
        try:
            while not self.stop_requested:
                gpio, _ = link.next_gpio()
                time_s = self._cart_time_s(gpio.time_ms)
                if duration_s is not None and time_s >= duration_s - 1e-9:
                    result.stopped = "duration"
                    break
                self._cart_tick = round(time_s * _TICKS_PER_S)
                self._accept(gpio, time_s)
            else:
                result.stopped = "interrupted"
        except PlantError as exc:
            result.stopped, result.failure = "fault", str(exc)
        except KeyboardInterrupt:
            result.stopped = "interrupted"
        if not self._decided:
            self._decide(None, self._looked[-1].floats[CH_FIRMWARE_ID] if self._looked else None)
        self._write_held()
        return result

    def _hold(self, write: Callable[[], None]) -> None:
        self._held.append(write)
        if self._decided:
            self._write_held()

    def _accept(self, gpio: Gpio, time_s: float) -> None:
        """Hold a frame; the first frames decide the labels, then what is held is written."""
        if not self._decided:
            self._looked.append(gpio)
            firmware = recognise_firmware(gpio.floats, gpio.ints)
            if firmware is not None or len(self._looked) >= RECOGNISE_FRAMES:
                self._decide(firmware, gpio.floats[CH_FIRMWARE_ID])
        self._hold(lambda: self._record(gpio, time_s))

    def _decide(self, firmware: Firmware | None, marker: float | None) -> None:
        """Choose the labels, say so (``marker``: float 6 of the deciding frame), open the sinks."""
        self._decided, self.firmware = True, firmware
        self.open(firmware_labels(firmware))
        if self.announce is not None and self.labels is not None:
            given = self.given_labels is not None
            self.announce(describe_labels(firmware, marker, self.labels, given=given))

    def _write_held(self) -> None:
        held, self._held = self._held, []
        for write in held:
            write()

    def _record(self, gpio: Gpio, time_s: float) -> None:
        # float32 values: their shortest text in the CSV is the float32's own
        row = [time_s, self.result.frames, *np.asarray(gpio.floats, np.float32), *gpio.ints]
        for sink in self.rows:
            sink.write(row)
        self.result.frames += 1
        self.result.duration_s = time_s

    def _log(self, entity: str, text: str) -> None:
        """A text, stamped with the last row's time and tick."""
        tick = max(0, self.result.frames - 1)
        for sink in self.texts:
            sink.log_text(entity, text, self.result.duration_s, tick, "INFO")

    def _cart_time_s(self, time_ms: int) -> float:
        """Cart time of this GPIO since the first (s): its tick (see the module) times Ts. The
        stamps follow their signed difference modulo 2³² from the previous one, so the u32 wrap is
        a step like any other; the tick advances in :meth:`run`, for the frames it keeps."""
        if self._last_ms is not None:
            half = _TIME_MODULO_MS // 2
            self._elapsed_ms += (time_ms - self._last_ms + half) % _TIME_MODULO_MS - half
        self._last_ms = time_ms
        tick = max(self._cart_tick + 1, round(self._elapsed_ms / _PERIOD_MS))
        return tick / _TICKS_PER_S  # a division: 0.03, not 3 × 0.01 = 0.030000000000000002
