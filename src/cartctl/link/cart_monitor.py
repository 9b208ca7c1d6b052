"""Passive recording of what a cart sends (``cartctl monitor``): labelled GPIO rows, text, events.

For carts that run their own controller (the exported C, or the course's own code): the monitor
never sends anything to the cart. It reads the cart's stream through
:class:`~cartctl.link.cart_link.CartLink` (same framing, silence timeout and port errors as the
serial plant) and turns each GPIO into one row::

    time_s   cart time since the first GPIO (s): k · Ts, k the cart's tick since the first GPIO
    tick     0, 1, 2, ...: one per GPIO received (a lost frame shows as a gap in time_s)

The cart sends one GPIO per 10 ms tick, stamped with its ``millis()`` (the GPIO's u32 time field,
which wraps after 49.7 days). Those stamps jitter by a millisecond, and a firmware that stamps the
frame when its communication thread sends it can give several frames one stamp and then jump. The
tick k of each frame is therefore counted, not read: k = max(k_prev + 1, round(Δms / 10 ms)) with
Δms the stamps' distance from the first's (followed modulo 2³²). Time is strictly increasing and a multiple of
Ts; a lost frame (a step of about 20 ms in the stamps) leaves a step of two ticks, and a burst of
equal stamps advances one tick per frame until the stamps catch up.
    f0..f7, i0..i3 under their labels: those given (``--labels``), else those of cartctl's
             firmware when its frames carry its marker (the bridge's ``speed_a, voltage_a, ...``,
             the on-board export's ``speed_a, voltage_a, reference_a, ...``:
             :mod:`cartctl.link.firmware_id`), else QRoboticsCenter's FloatIn0..7, IntIn0..3

PRINT lines and EVENT messages (QRC's buttons) are stamped with the time and tick of the last GPIO
before them (0 before the first).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from cartctl.cart import PERIOD_S
from cartctl.errors import InputError, PlantError
from cartctl.link.cart_link import CartLink
from cartctl.link.dialect import GPIO_FLOAT_COUNT, GPIO_INT_COUNT
from cartctl.link.firmware_id import CH_FIRMWARE_ID, CHANNEL_KEYS, Firmware, recognise_firmware
from cartctl.link.framer import Event, Gpio, Message

FLOAT_CHANNELS = GPIO_FLOAT_COUNT
INT_CHANNELS = GPIO_INT_COUNT
DEFAULT_LABELS: tuple[str, ...] = (
    *(f"FloatIn{i}" for i in range(FLOAT_CHANNELS)),
    *(f"IntIn{i}" for i in range(INT_CHANNELS)),
)
"""QRoboticsCenter's default labels, in :data:`CHANNEL_KEYS` order."""
TIME_COLUMN, TICK_COLUMN = "time_s", "tick"
_LABEL = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_TIME_MODULO_MS = 1 << 32  # the GPIO's time field is a u32 of milliseconds
_PERIOD_MS = PERIOD_S * 1000.0
_TICKS_PER_S = round(1.0 / PERIOD_S)
RECOGNISE_FRAMES = 10
"""The frames (100 ms) in which one carrying a firmware marker is waited for before the labels
are chosen: a firmware's first frames may go out before its first ``control()`` filled them."""


def parse_labels(text: str | None) -> tuple[str, ...]:
    """The 12 channel labels, in :data:`CHANNEL_KEYS` order, from ``f0=speed_a,i0=echo,...``.

    Channels not named keep their default label (:data:`DEFAULT_LABELS`).

    Raises
    ------
    InputError
        An item is not ``key=label``, a key is not f0..f7 or i0..i3 or is given twice, a label is
        not an identifier (letters, digits, '_', not starting with a digit), or two channels end
        up with the same label (or one is named ``time_s`` or ``tick``).
    """
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
    """The 12 channel labels, in :data:`CHANNEL_KEYS` order, of a firmware's channels.

    The channels it names get its labels (``speed_a``, ``voltage_a``, ...); the others, and
    every channel of an unknown firmware (None), keep QRoboticsCenter's (:data:`DEFAULT_LABELS`).
    """
    labels = dict(zip(CHANNEL_KEYS, DEFAULT_LABELS, strict=True))
    if firmware is not None:
        labels.update(firmware.labels)
    return tuple(labels.values())


def describe_labels(
    firmware: Firmware | None, marker: float | None, labels: Sequence[str], *, given: bool
) -> str:
    """One line: which firmware the cart runs (or that it is not cartctl's) and the labels used.

    Parameters
    ----------
    firmware : Firmware or None
        What :func:`~cartctl.link.firmware_id.recognise_firmware` found; None for another one.
    marker : float or None
        The value of float channel 6 it was told by (None: no frame came).
    labels : sequence of str
        The 12 labels used, in :data:`CHANNEL_KEYS` order.
    given : bool
        Whether they came from ``--labels``.
    """
    told = "no frame came" if marker is None else f"float {CH_FIRMWARE_ID} = {marker:g}"
    what = firmware.name if firmware is not None else "not one of cartctl's"
    named = ",".join(
        f"{key}={label}"
        for key, label, default in zip(CHANNEL_KEYS, labels, DEFAULT_LABELS, strict=True)
        if label != default
    )
    if not named:
        used = "QRoboticsCenter's labels (FloatIn0..7, IntIn0..3)"
        if not given:
            used += "; name the channels with --labels"
    else:
        used = f"labels {'from --labels ' if given else ''}{named}, the others QRoboticsCenter's"
    return f"firmware: {what}, by {told}; {used}"


class RowSink(Protocol):
    """Where rows go (``CsvSink``, the channels Rerun sink)."""

    def open(self, columns: Sequence[str]) -> None: ...
    def write(self, row: Sequence[float]) -> None: ...
    def close(self) -> None: ...


class TextSink(Protocol):
    """Where the cart's text and events go (the channels Rerun sink)."""

    def log_text(self, entity: str, text: str, time_s: float, tick: int, level: str) -> None: ...


PRINT_ENTITY, EVENT_ENTITY = "cart/print", "cart/events"


class MonitorLink(CartLink):
    """A :class:`CartLink` that also hands the EVENT messages it reads to ``on_event``.

    ``next_gpio`` (silence timeout, vanished port) skips every message that is not a GPIO; this
    link reports the EVENTs among them before they are skipped.
    """

    def __init__(self, port: str, *, on_event: Callable[[Event], None], **kwargs: Any) -> None:
        super().__init__(port, **kwargs)
        self.on_event = on_event

    def _next_message(self, timeout_s: float) -> Message | None:
        message = super()._next_message(timeout_s)
        if isinstance(message, Event):
            self.on_event(message)
        return message


@dataclass
class MonitorResult:
    """What a monitor run saw, and why it stopped."""

    frames: int = 0
    """GPIO rows recorded."""
    duration_s: float = 0.0
    """Cart time of the last row (s since the first)."""
    print_lines: int = 0
    events: int = 0
    stopped: str = "duration"
    """'duration', 'interrupted' (Ctrl-C) or 'fault'."""
    failure: str | None = None


class Monitor:
    """Reads a connected link and writes one row per GPIO to the sinks (``time_s, tick, labels``).

    The labels are chosen from what the cart sends: the first of its first
    :data:`RECOGNISE_FRAMES` frames that carries the marker of one of cartctl's firmwares
    (:func:`~cartctl.link.firmware_id.recognise_firmware`) names the channels
    (:func:`firmware_labels`); without one they are QRoboticsCenter's. Labels given here override
    them (the firmware is still told). The sinks are opened once the labels are chosen, with
    the frames until then written at once, so nothing is lost or re-stamped.

    Parameters
    ----------
    rows : sequence of RowSink
        Opened here with ``time_s, tick, <12 labels>``; closed by the caller.
    texts : sequence of TextSink
        Receive the PRINT lines and EVENTs.
    labels : sequence of str, optional
        The 12 channel labels (:func:`parse_labels`); None chooses them from the frames.
    echo : callable, optional
        Also receives each PRINT line (e.g. to show it on stderr).
    announce : callable, optional
        Receives the one line of :func:`describe_labels` once the labels are chosen.
    """

    def __init__(
        self,
        rows: Sequence[RowSink],
        texts: Sequence[TextSink],
        labels: Sequence[str] | None = None,
        *,
        echo: Callable[[str], None] | None = None,
        announce: Callable[[str], None] | None = None,
    ) -> None:
        self.rows, self.texts, self.echo, self.announce = list(rows), list(texts), echo, announce
        self.given_labels = None if labels is None else tuple(labels)
        self.labels: tuple[str, ...] | None = None
        """The labels in use, once chosen (:meth:`open`, or the first frames)."""
        self.columns: tuple[str, ...] | None = None
        self.firmware: Firmware | None = None
        """The firmware the cart's frames named, once they were looked at (None: not cartctl's)."""
        self.result = MonitorResult()
        self.stop_requested = False
        self._decided = False  # whether the frames were looked at for a firmware
        self._pending: list[tuple[list[tuple[str, str, str]], Gpio, float]] = []
        self._last_ms: int | None = None  # the previous GPIO's stamp (ms)
        self._elapsed_ms = 0  # the stamps' distance from the first GPIO's (ms)
        self._cart_tick = -1  # the cart's tick of the last row, since the first GPIO
        self._time_s = 0.0
        self._texts: list[tuple[str, str, str]] = []  # (entity, text, level) to stamp and record

    def on_print(self, line: str) -> None:
        """CartLink's PRINT callback: queue the line for the next stamp."""
        self._texts.append((PRINT_ENTITY, line, "INFO"))
        self.result.print_lines += 1
        if self.echo is not None:
            self.echo(line)

    def on_event(self, event: Event) -> None:
        """MonitorLink's EVENT callback: queue it for the next stamp."""
        button = event.button
        text = f"button {button} pressed" if button is not None else f"event {event.type}"
        self._texts.append((EVENT_ENTITY, text, "INFO"))
        self.result.events += 1

    def open(self) -> None:
        """Open the row sinks with the columns: the labels given, else those chosen so far
        (QRoboticsCenter's before any frame). Once only; the labels are then fixed."""
        if self.columns is not None:
            return
        self.labels = self.given_labels or self.labels or DEFAULT_LABELS
        self.columns = (TIME_COLUMN, TICK_COLUMN, *self.labels)
        for sink in self.rows:
            sink.open(self.columns)

    def run(self, link: CartLink, duration_s: float | None = None) -> MonitorResult:
        """Record until ``duration_s`` of cart time, a stop request or a line fault.

        The GPIO whose cart time (since the first) reaches ``duration_s`` is not recorded, so a
        run of S seconds holds S / 0.01 rows. A :class:`~cartctl.errors.PlantError` (silence,
        vanished port) ends the run with ``stopped = 'fault'``; :attr:`stop_requested` (set from a
        signal handler) or a KeyboardInterrupt with ``'interrupted'``. Nothing is raised for them.
        However it ends, the sinks are open (labels chosen from the frames that came) and hold
        every frame kept.
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
            last = self._pending[-1][1].floats[CH_FIRMWARE_ID] if self._pending else None
            self._decide(None, last)
        self._write_pending()
        self._flush_texts()
        return result

    def _accept(self, gpio: Gpio, time_s: float) -> None:
        """Keep a frame (with the texts that came before it); write it once the labels are
        chosen, which the first frames decide."""
        self._pending.append((self._texts, gpio, time_s))
        self._texts = []
        if not self._decided:
            firmware = recognise_firmware(gpio.floats, gpio.ints)
            if firmware is None and len(self._pending) < RECOGNISE_FRAMES:
                return
            self._decide(firmware, gpio.floats[CH_FIRMWARE_ID])
        self._write_pending()

    def _decide(self, firmware: Firmware | None, marker: float | None) -> None:
        """Choose the labels (given, the firmware's, or the defaults), say so, open the sinks.

        ``marker`` is float 6 of the frame that told the firmware (the last one looked at when
        none did; None without frames).
        """
        self._decided = True
        self.firmware = firmware
        if self.columns is None:
            self.labels = self.given_labels or firmware_labels(firmware)
        self.open()
        if self.announce is not None and self.labels is not None:
            given = self.given_labels is not None
            self.announce(describe_labels(firmware, marker, self.labels, given=given))

    def _write_pending(self) -> None:
        """Write the frames kept, each after the texts that came before it."""
        pending, self._pending = self._pending, []
        later, self._texts = self._texts, []
        for texts, gpio, time_s in pending:
            self._texts = texts
            self._flush_texts()
            self._record(gpio, time_s)
        self._texts = later + self._texts

    def _cart_time_s(self, time_ms: int) -> float:
        """Cart time of this GPIO since the first (s): its tick (see the module) times Ts.

        The stamps are followed by their signed difference modulo 2³² from the previous one, so
        the u32 counter's wrap is a step like any other and a stamp a little behind its
        predecessor is not read as 49 days ahead. Does not advance the tick: :meth:`run`
        does, for the frames it keeps.
        """
        if self._last_ms is not None:
            half = _TIME_MODULO_MS // 2
            self._elapsed_ms += (time_ms - self._last_ms + half) % _TIME_MODULO_MS - half
        self._last_ms = time_ms
        tick = max(self._cart_tick + 1, round(self._elapsed_ms / _PERIOD_MS))
        return tick / _TICKS_PER_S  # a division: 0.03, not 3 × 0.01 = 0.030000000000000002

    def _record(self, gpio: Gpio, time_s: float) -> None:
        # float32 values: their shortest text in the CSV is the float32's own
        row = [time_s, self.result.frames, *np.asarray(gpio.floats, np.float32), *gpio.ints]
        for sink in self.rows:
            sink.write(row)
        self._time_s = time_s
        self.result.frames += 1
        self.result.duration_s = time_s

    def _flush_texts(self) -> None:
        texts = self._texts
        if not texts:
            return
        tick = max(0, self.result.frames - 1)
        for entity, text, level in texts:
            for sink in self.texts:
                sink.log_text(entity, text, self._time_s, tick, level)
        texts.clear()


def wait_started(link: CartLink, timeout_s: float) -> None:
    """Wait for the cart's HEARTBEAT at the bridge's 500 kbaud or the course firmware's 115200
    (:meth:`CartLink.wait_heartbeat_any_rate`), closing the link on failure."""
    try:
        link.wait_heartbeat_any_rate(timeout_s)
    except BaseException:
        link.close()
        raise
