"""Stand-ins for the monitor's row and text sinks and for a cart link, playing a script."""

from __future__ import annotations

from collections.abc import Sequence

from cartctl.errors import PlantError
from cartctl.link.cart_monitor import Monitor
from cartctl.link.dialect import Event, Gpio


class MemoryRows:
    """A row sink that keeps what it is given; opened once, written only after it is opened."""

    def __init__(self) -> None:
        self.columns: list[str] | None = None
        self.rows: list[list[float]] = []

    def open(self, columns: Sequence[str]) -> None:
        assert self.columns is None, "opened once"
        self.columns = list(columns)

    def write(self, row: Sequence[float]) -> None:
        assert self.columns is not None, "written after open"
        self.rows.append([float(v) for v in row])

    def close(self) -> None:
        pass


class MemoryTexts:
    """A text sink keeping ``(entity, text, time_s, tick)``."""

    def __init__(self) -> None:
        self.texts: list[tuple[str, str, float, int]] = []

    def log_text(self, entity: str, text: str, time_s: float, tick: int, level: str) -> None:
        self.texts.append((entity, text, time_s, tick))


class ScriptedLink:
    """``next_gpio`` of a CartLink, playing a script of GPIOs, PRINT lines and EVENTs, then a
    line fault."""

    def __init__(self, monitor: Monitor, script: list[object]) -> None:
        self.monitor, self.script = monitor, list(script)

    def next_gpio(self) -> tuple[Gpio, float]:
        while self.script:
            item = self.script.pop(0)
            if isinstance(item, Gpio):
                return item, 0.0
            if isinstance(item, Event):
                self.monitor.on_event(item)
            else:
                self.monitor.on_print(str(item))
        raise PlantError("no data from the cart on /dev/fake for 100 ms")
