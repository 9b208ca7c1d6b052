"""The plant interface: what the loop and the experiments talk to, one tick at a time.

As in a trace's rows, row k holds the voltage *commanded* at tick k and the speed *measured* at
tick k::

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
    """Two motors advanced one tick (``period_s``, s) at a time, in the module docstring's order;
    ``close`` leaves the motors at zero volts and releases any resource."""

    period_s: float

    def reset(self) -> Measurement: ...

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement: ...

    def close(self) -> None: ...


@runtime_checkable
class ClockedPlant(Plant, Protocol):
    """A plant that sets the pace itself: the real or the virtual cart over serial.

    ``receive`` returns when the cart's next tick arrives (``step`` is ``send`` then ``receive``,
    called apart to time the loop's compute without the wait). ``arrival_s``: host time
    (``time.perf_counter``) of the latest measurement; ``tick_index``: its cart tick, counted from
    the run's tick 0 (gaps included); ``connect`` opens the line and waits for the cart.
    """

    arrival_s: float
    tick_index: int

    def connect(self) -> None: ...

    def send(self, voltage_a_v: float, voltage_b_v: float) -> None: ...

    def receive(self) -> Measurement: ...
