"""Passive recording of what a cart sends (``cartctl monitor``): labelled GPIO rows, text, events.

For carts that run their own controller (the exported C, or the course's own code): the monitor
never sends anything to the cart. It reads the cart's stream through
:class:`~cartctl.plants.cart_link.CartLink` (same framing, silence timeout and port errors as the
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
    f0..f7, i0..i3 under their labels (QRoboticsCenter's FloatIn0..7, IntIn0..3 by default)

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
from cartctl.link import Event, Gpio, Message
from cartctl.plants.cart_link import CartLink

FLOAT_CHANNELS = 8
INT_CHANNELS = 4
CHANNEL_KEYS: tuple[str, ...] = (
    *(f"f{i}" for i in range(FLOAT_CHANNELS)),
    *(f"i{i}" for i in range(INT_CHANNELS)),
)
"""Channel keys in row order: float channels f0..f7, then int channels i0..i3."""
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

    Parameters
    ----------
    rows : sequence of RowSink
        Opened here with ``time_s, tick, <12 labels>``; closed by the caller.
    texts : sequence of TextSink
        Receive the PRINT lines and EVENTs.
    labels : sequence of str
        The 12 channel labels (:func:`parse_labels`).
    echo : callable, optional
        Also receives each PRINT line (e.g. to show it on stderr).
    """

    def __init__(
        self,
        rows: Sequence[RowSink],
        texts: Sequence[TextSink],
        labels: Sequence[str],
        *,
        echo: Callable[[str], None] | None = None,
    ) -> None:
        self.rows, self.texts, self.echo = list(rows), list(texts), echo
        self.columns = (TIME_COLUMN, TICK_COLUMN, *labels)
        self.result = MonitorResult()
        self.stop_requested = False
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
        """Open the row sinks with the columns."""
        for sink in self.rows:
            sink.open(self.columns)

    def run(self, link: CartLink, duration_s: float | None = None) -> MonitorResult:
        """Record until ``duration_s`` of cart time, a stop request or a line fault.

        The GPIO whose cart time (since the first) reaches ``duration_s`` is not recorded, so a
        run of S seconds holds S / 0.01 rows. A :class:`~cartctl.errors.PlantError` (silence,
        vanished port) ends the run with ``stopped = 'fault'``; :attr:`stop_requested` (set from a
        signal handler) or a KeyboardInterrupt with ``'interrupted'``. Nothing is raised for them.
        """
        result = self.result
        try:
            while not self.stop_requested:
                gpio, _ = link.next_gpio()
                self._flush_texts()
                time_s = self._cart_time_s(gpio.time_ms)
                if duration_s is not None and time_s >= duration_s - 1e-9:
                    result.stopped = "duration"
                    break
                self._record(gpio, time_s)
            else:
                result.stopped = "interrupted"
        except PlantError as exc:
            result.stopped, result.failure = "fault", str(exc)
        except KeyboardInterrupt:
            result.stopped = "interrupted"
        self._flush_texts()
        return result

    def _cart_time_s(self, time_ms: int) -> float:
        """Cart time of this GPIO since the first (s): its tick (see the module) times Ts.

        The stamps are followed by their signed difference modulo 2³² from the previous one, so
        the u32 counter's wrap is a step like any other and a stamp a little behind its
        predecessor is not read as 49 days ahead. Does not advance the tick: :meth:`_record`
        does, for the rows it keeps.
        """
        if self._last_ms is not None:
            half = _TIME_MODULO_MS // 2
            self._elapsed_ms += (time_ms - self._last_ms + half) % _TIME_MODULO_MS - half
        self._last_ms = time_ms
        tick = max(self._cart_tick + 1, round(self._elapsed_ms / _PERIOD_MS))
        return tick / _TICKS_PER_S  # a division: 0.03, not 3 × 0.01 = 0.030000000000000002

    def _record(self, gpio: Gpio, time_s: float) -> None:
        # float32 values: their shortest text in the CSV is the float32's own
        self._cart_tick = round(time_s * _TICKS_PER_S)
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
