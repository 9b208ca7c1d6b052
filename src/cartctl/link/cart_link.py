"""The host's end of the serial line to a microOS cart: port, framing, sign of life, silence,
each way the line can fail turned into one clear error.
"""

from __future__ import annotations

import collections
import contextlib
import errno
import functools
import os
import stat
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import cartctl.link.dialect as dialect
from cartctl.choices import DEFAULT_CONNECT_TIMEOUT_S
from cartctl.errors import CartctlError, InputError, PlantError
from cartctl.link.bridge import BRIDGE_BAUD, LEGACY_BAUD

DEFAULT_SILENCE_TIMEOUT_S = 0.1
"""No GPIO for this long (10 ticks) ends a run: the cart's own watchdog trips at the same age."""
READ_SLICE_S = 0.005  # a read returns after the first byte, or after this long without one
COUNTED_SLICE_S = 2 * READ_SLICE_S
"""Silence counts the time the host listened: a read the PC held up longer (a busy machine, a
garbage collection, an emulated cart paused with this process) counts as this much."""
LEGACY_LISTEN_S = 1.5  # at 115200 baud: a HEARTBEAT every 1.1 s, a GPIO every 10 ms


class UnsupportedCartError(CartctlError):
    """The cart speaks a firmware generation cartctl does not (exit 2: flash the bridge sketch)."""


def _ports_hint() -> str:
    """``serial ports present: ...`` as the OS lists them (a courtesy: never fails)."""
    try:
        from serial.tools import list_ports

        ports = sorted(p.device for p in list_ports.comports())
    except Exception:
        ports = []
    return "serial ports present: " + (", ".join(ports) if ports else "none")


def _no_port(port: str, what: str = "is not a serial device (no terminal)") -> InputError:
    return InputError(f"serial port {port} {what}; {_ports_hint()}")


def check_port(port: str) -> None:
    """A typo, not a fault (InputError): ``port`` is not there, or is a folder or a file, or (where
    sysfs says, without opening it) a character device that is no terminal (``/dev/null``)."""
    if not os.path.exists(port):
        raise _no_port(port, "does not exist")
    device = os.stat(port)
    if not stat.S_ISCHR(device.st_mode):
        what = "is a folder, not" if os.path.isdir(port) else "is not"
        raise _no_port(port, f"{what} a serial device")
    kind = f"/sys/dev/char/{os.major(device.st_rdev)}:{os.minor(device.st_rdev)}/subsystem"
    if os.path.exists(kind) and os.path.basename(os.path.realpath(kind)) != "tty":
        raise _no_port(port)


def print_to_stderr(line: str) -> None:
    """Default for the cart's PRINT lines: ``cart: TEXT`` on stderr (stdout may carry JSON)."""
    print(f"cart: {line}", file=sys.stderr, flush=True)


class CartLink:
    """A serial connection to a generation-A microOS cart (500 kbaud for the bridge, 115200 before).

    ``on_print`` receives each PRINT line (default :func:`print_to_stderr`), ``on_event`` each
    EVENT, ``serial_factory`` opens the port (default ``serial.Serial``; for tests).
    """

    def __init__(
        self,
        port: str,
        *,
        silence_timeout_s: float = DEFAULT_SILENCE_TIMEOUT_S,
        on_print: Callable[[str], None] | None = None,
        on_event: Callable[[dialect.Event], None] | None = None,
        serial_factory: Callable[..., Any] | None = None,
    ) -> None:
        self.port = port
        self.baud = BRIDGE_BAUD
        self.silence_timeout_s = float(silence_timeout_s)
        self.on_print = on_print or print_to_stderr
        self.on_event = on_event
        self._factory = serial_factory
        self.framer = dialect.Framer()
        self.lines = dialect.LineAssembler()
        self._pending: collections.deque[dialect.Message] = collections.deque()
        self._serial: Any = None
        self.failure: str | None = None  # why the stream stopped (silence, a vanished port)
        self.vanished = False  # the port itself is gone: nothing can be sent any more
        # per THREAD_INFO id, the largest duration field seen (the bridge's timing reports;
        # cleared by whoever starts counting)
        self.thread_maxima: dict[int, int] = {}

    @property
    def stats(self) -> dialect.LinkStats:
        return self.framer.stats

    def open(self) -> None:
        """Open the port at :attr:`baud` 8N1, no flow control."""
        import serial

        # one program at a time (a lock): two would split the cart's bytes between them
        factory = self._factory or functools.partial(serial.Serial, exclusive=True)
        if self._factory is None:
            check_port(self.port)
        try:
            self._serial = factory(self.port, self.baud, timeout=READ_SLICE_S, write_timeout=0.5)
        except (OSError, serial.SerialException) as exc:
            if getattr(exc, "errno", None) == errno.EAGAIN:  # another program holds the lock
                raise PlantError(
                    f"serial port {self.port} is in use by another program (a "
                    "cartctl monitor or run still open?)"
                ) from None
            if getattr(exc.__context__, "args", ())[:1] == (errno.ENOTTY,):  # termios: /dev/null
                raise _no_port(self.port) from None
            reason = getattr(exc, "strerror", None) or str(exc)
            raise PlantError(
                f"cannot open serial port {self.port}: {reason}; {_ports_hint()}"
            ) from None

    def _listen(self, kinds: tuple[type, ...], timeout_s: float) -> bool:
        """Read until a message of ``kinds`` (PRINT lines shown on the way); False on timeout."""
        deadline = time.perf_counter() + timeout_s
        while (remaining := deadline - time.perf_counter()) > 0:
            if isinstance(self._next_message(remaining), kinds):
                return True
        return False

    def wait_heartbeat_any_rate(self, timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S) -> int:
        """Wait for the cart's HEARTBEAT at :attr:`baud`, else listen at 115200 baud (the port stays
        open, so a real Mega is not reset again); return the rate it answered at, now :attr:`baud`.
        Nothing at either rate raises PlantError (about the first rate), generation-B frames
        :class:`UnsupportedCartError`; either way the link is closed."""
        try:
            if self._listen((dialect.Heartbeat,), timeout_s):
                return self.baud
            heard = self.stats.frames + self.stats.garbage_bytes
            error = PlantError(
                f"no HEARTBEAT from a cart on {self.port} within {timeout_s:g} s (received "
                f"{'bytes but no HEARTBEAT' if heard else 'nothing'}); is the cart on, running the "
                f"bridge sketch (firmware/), and on this port? {_ports_hint()}"
            )
            if self.baud != LEGACY_BAUD:
                with contextlib.suppress(OSError, ValueError, AttributeError):
                    self._serial.baudrate = LEGACY_BAUD
                    self.framer = dialect.Framer()
                    self._pending.clear()
                    if self._listen((dialect.Heartbeat, dialect.Gpio), LEGACY_LISTEN_S):
                        self.baud = LEGACY_BAUD
                        return LEGACY_BAUD
            raise error
        except BaseException:
            self.close()
            raise

    def next_gpio(self, timeout_s: float | None = None) -> tuple[dialect.Gpio, float]:
        """The next GPIO and the host time it arrived (``time.perf_counter`` s). Raises PlantError
        after ``timeout_s`` (default :attr:`silence_timeout_s`) of listening without one (see
        :data:`COUNTED_SLICE_S`) or when the port vanished, UnsupportedCartError on generation B."""
        wait_s = self.silence_timeout_s if timeout_s is None else timeout_s
        listened_s = 0.0
        while listened_s < wait_s:
            started_s = time.perf_counter()
            message = self._next_message(min(READ_SLICE_S, wait_s - listened_s))
            if isinstance(message, dialect.Gpio):
                return message, time.perf_counter()
            listened_s += min(time.perf_counter() - started_s, COUNTED_SLICE_S)
        self.failure = (
            f"no data from the cart on {self.port} for {wait_s * 1000:.0f} ms "
            "(cable pulled, cart stalled or reset)"
        )
        raise PlantError(self.failure)

    def gpio_waiting(self, wait_s: float = 0.0) -> bool:
        """Whether a complete GPIO is buffered (the host is behind the cart) or comes in ``wait_s``."""
        self._poll(0.0)
        return self._wait_for(lambda: dialect.Gpio in map(type, self._pending), wait_s)

    def _next_message(self, timeout_s: float) -> dialect.Message | None:
        """One decoded message, or None when ``timeout_s`` passed without one."""
        if not self._wait_for(lambda: bool(self._pending), timeout_s):
            return None
        message = self._pending.popleft()
        if isinstance(message, dialect.Event) and self.on_event is not None:
            self.on_event(message)
        return message

    def _wait_for(self, ready: Callable[[], bool], timeout_s: float) -> bool:
        """Poll the port until ``ready()``; False when ``timeout_s`` passed first."""
        deadline = time.perf_counter() + timeout_s
        while not ready():
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return False
            self._poll(remaining)
        return True

    def _poll(self, timeout_s: float) -> None:
        """Read what the port has (up to :data:`READ_SLICE_S` for a first byte) and decode it."""
        with self._port() as ser:
            waiting = ser.in_waiting
            data = ser.read(max(1, waiting)) if waiting or timeout_s > 0 else b""
        for message in self.framer.feed(data) if data else ():
            if isinstance(message, dialect.PrintText):
                for line in self.lines.feed(message.text):
                    self.on_print(line)
            elif isinstance(message, dialect.ThreadInfo):
                payload = message.payload  # the last duration: uint16 at 16, the thread id at 20
                duration, thread = payload[16] | (payload[17] << 8), payload[20]
                self.thread_maxima[thread] = max(self.thread_maxima.get(thread, 0), duration)
            elif isinstance(message, dialect.GenerationBFrame):
                raise UnsupportedCartError(
                    f"the cart on {self.port} speaks microOS generation B (MAVLink 2, GPIOX "
                    "messages); cartctl speaks generation A (MAVLink 1, GPIO): flash the bridge "
                    "sketch of firmware/ (see firmware/README.md)"
                )
            else:
                self._pending.append(message)

    @contextlib.contextmanager
    def _port(self) -> Iterator[Any]:
        """The open port; a failing read or write means it vanished (PlantError)."""
        if self._serial is None:
            raise PlantError(f"serial port {self.port} is not open")
        try:
            yield self._serial
        except Exception as exc:  # pyserial raises SerialException or OSError when the device goes
            self.vanished = True
            self.failure = f"serial port {self.port} vanished ({exc}); cable pulled?"
            raise PlantError(self.failure) from None

    def send(self, frame: bytes) -> None:
        """Write one frame; a vanished port raises :class:`~cartctl.errors.PlantError`."""
        with self._port() as ser:
            ser.write(frame)

    def close(self) -> None:
        """Flush what was written, close the port and show the cart's unfinished PRINT line (a last
        text without a newline); never raises."""
        ser, self._serial = self._serial, None
        if ser is None:
            return
        with contextlib.suppress(Exception):
            if not self.vanished:
                ser.flush()
        with contextlib.suppress(Exception):
            ser.close()
        with contextlib.suppress(Exception):
            if (rest := self.lines.flush()) is not None:
                self.on_print(rest)
