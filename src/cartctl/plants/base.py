"""The plant interface: what the loop and the experiments talk to.

A plant is advanced one control tick at a time. The tick convention matches a trace's rows (the
trace CSV): row k holds the voltage *commanded* at tick k and the speed *measured* at tick k.

    y0 = plant.reset()            # speeds measured at tick 0
    for k in range(n):
        u = controller(y)         # voltages commanded at tick k
        y = plant.step(u_a, u_b)  # speeds measured at tick k + 1

Every delay (the ZOH, the firmware's one-tick delay, a serial link) lives inside the plant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable


@dataclass(frozen=True, slots=True)
class Measurement:
    """What a plant reports at one tick: the measured wheel speeds (rad/s, as the cart reports
    them) and, where the plant knows them (simulators; None on hardware), the unquantised ones."""

    speed_a_rad_s: float
    speed_b_rad_s: float
    true_speed_a_rad_s: float | None = None
    true_speed_b_rad_s: float | None = None


@runtime_checkable
class Plant(Protocol):
    """Two motors advanced one tick at a time (see the module docstring for the convention)."""

    period_s: float
    """The tick period (s)."""

    def reset(self) -> Measurement:
        """Return the plant to rest and give the measurement at tick 0."""
        ...

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        """Command these voltages (V) at the current tick, advance one tick, and measure."""
        ...

    def close(self) -> None:
        """Leave the motors at zero volts and release any resource."""
        ...


@runtime_checkable
class ClockedPlant(Plant, Protocol):
    """A plant that sets the pace itself: the real cart (or the virtual one) over serial.

    Each :meth:`receive` returns when the cart's next tick arrives, so the loop runs at the cart's
    10 ms and not on the host's clock. :meth:`step` is :meth:`send` then :meth:`receive`; the loop
    calls them apart to time its own compute without the wait.
    """

    arrival_s: float
    """Host time (``time.perf_counter``, s) when the latest measurement arrived."""
    tick_index: int
    """The latest measurement's cart tick, counted from the run's tick 0 (gaps included)."""

    def connect(self) -> None:
        """Open the line and wait for the cart (raises a clear error if it is not there)."""
        ...

    def send(self, voltage_a_v: float, voltage_b_v: float) -> None:
        """Send this tick's voltages (V)."""
        ...

    def receive(self) -> Measurement:
        """Wait for the cart's next tick and return its measurement."""
        ...
