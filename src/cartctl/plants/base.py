"""The plant interface: what the loop and the experiments talk to.

A plant is advanced one control tick at a time. The tick convention matches contract 1 (the
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
    """What a plant reports at one tick.

    Attributes
    ----------
    speed_a_rad_s, speed_b_rad_s : float
        Measured wheel speeds (rad/s), as the cart reports them.
    true_speed_a_rad_s, true_speed_b_rad_s : float or None
        The unquantised wheel speeds (rad/s) at the tick instant, where the plant knows them
        (simulators); None for real hardware.
    """

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
