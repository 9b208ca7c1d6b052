"""A designed controller running on the (virtual) cart itself, as the exported C does.

``cartctl export CONTROLLER.toml --arduino`` writes C for the course template's ``control()``;
:class:`OnboardFirmware` is the same thing in Python for :class:`~cartctl.plants.virtual_cart.VirtualCart`
(``cartctl virtual-cart --onboard``, ``cartctl monitor virtual --onboard``). Per tick::

    io()       the virtual cart applies the voltage returned at the previous tick, reads speeds
    control()  reference r (see below), u = controller.step(r, measured speed), per motor;
               u is returned and reaches the motor at the next io(): one tick of delay, as on
               the real cart, instead of a PC-side loop's several

Channels, as in the export snippet (:mod:`cartctl.export.arduino`):

- in: float 0 = reference A, float 1 = reference B (rad/s), held from the host's last GPIO;
- out: float 0/1 = speed A/B (rad/s), 2/3 = voltage A/B computed at this tick (V, applied at
  the next tick), 4/5 = reference A/B (rad/s); the int channels stay 0.

The reference comes from a reference spec (``step:8``, see :mod:`cartctl.reference`)
when one is given, with tick 0 at the cart's first ``control()``; otherwise from the held input
float channels, exactly as the exported snippet reads them. The controllers run the fixed
(steady-state) Kalman gain where they have an estimator, as the C does. The template's
``controlEnabled()`` (QRC button 0) is not modelled: the controller always runs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cartctl.design.build import build_controllers
from cartctl.design.controllerfile import load_controller
from cartctl.errors import InputError
from cartctl.export.arduino import as_steady_state
from cartctl.plants.bridge_firmware import CartIO
from cartctl.runtime.base import Controller
from cartctl.reference import reference_signal

CART_PERIOD_S = 0.01
"""The period of the cart's control thread (s)."""
IN_REFERENCE = {"a": 0, "b": 1}
"""Input float channel of each motor's reference (rad/s)."""
OUT_SPEED, OUT_VOLTAGE, OUT_REFERENCE = 0, 2, 4
"""First output float channel of the speeds, voltages and references (A, then B)."""
MOTORS = ("a", "b")
_FIRST_BLOCK_TICKS = 6000  # 60 s of reference; doubled whenever a run goes beyond it


class _Schedule:
    """A reference spec evaluated on the tick grid, extended on demand (specs are open-ended)."""

    def __init__(self, spec: str, period_s: float, motor: str) -> None:
        self.spec, self.period_s, self.motor = spec, period_s, motor
        self._values: NDArray[np.float64] = reference_signal(
            spec, _FIRST_BLOCK_TICKS, period_s, motor
        )

    def at(self, tick: int) -> float:
        """The reference (rad/s) at ``tick`` (0-based)."""
        if tick >= len(self._values):
            n = max(2 * len(self._values), tick + 1)
            self._values = reference_signal(self.spec, n, self.period_s, self.motor)
        return float(self._values[tick])


class OnboardFirmware:
    """``control()`` running one controller per motor on the cart (a ``CartFirmware``).

    Parameters
    ----------
    controllers : mapping of str to Controller
        The runtime controller of each motor ('a', 'b'); a motor without one gets 0 V.
    reference : str, optional
        Reference spec of both motors; None reads the held input float channels 0 and 1.
    period_s : float
        The cart's tick (s), the period the controllers were designed for.
    """

    ready_text = "cartctl on-board controller ready"

    def __init__(
        self,
        controllers: Mapping[str, Controller],
        *,
        reference: str | None = None,
        period_s: float = CART_PERIOD_S,
    ) -> None:
        unknown = sorted(set(controllers) - set(MOTORS))
        if unknown:
            raise InputError(f"the cart has motors a and b, not {', '.join(unknown)}")
        self.controllers = dict(controllers)
        self.reference = reference
        self.period_s = float(period_s)
        self._schedules = (
            None
            if reference is None
            else {m: _Schedule(reference, self.period_s, m) for m in self.controllers}
        )
        self.reset()

    @classmethod
    def from_file(cls, path: str | Path, *, reference: str | None = None) -> OnboardFirmware:
        """The controllers of a controller file, as the exported C runs them.

        Raises
        ------
        InputError
            The file was designed for another period than the cart's 10 ms, or a bad reference.
        MissingFileError, DataFileError
            The file is missing or does not hold a controller.
        """
        controller = load_controller(path)
        if not math.isclose(controller.period_s, CART_PERIOD_S, rel_tol=1e-9):
            raise InputError(
                f"{path} was designed for a period of {controller.period_s:g} s; the cart's "
                f"control() runs every {CART_PERIOD_S:g} s"
            )
        controllers = build_controllers(as_steady_state(controller))
        return cls(controllers, reference=reference, period_s=controller.period_s)

    def reset(self) -> None:
        """Power-on state: channels 0, controllers at rest, tick 0."""
        self.in_floats: list[float] = [0.0] * 8
        self.in_ints: list[int] = [0] * 4
        self.out_floats: list[float] = [0.0] * 8
        self.out_ints: list[int] = [0] * 4
        self.tick = 0
        for controller in self.controllers.values():
            controller.reset()

    def receive(self, floats: Sequence[float], ints: Sequence[int], now_ms: int = 0) -> None:
        """A GPIO from the host: every input channel is overwritten and then held."""
        self.in_floats = [float(v) for v in floats]
        self.in_ints = [int(v) for v in ints]

    def reference_at(self, motor: str) -> float:
        """The reference (rad/s) of ``motor`` at the current tick."""
        if self._schedules is not None:
            return self._schedules[motor].at(self.tick)
        return self.in_floats[IN_REFERENCE[motor]]

    def control(self, io: CartIO, now_ms: int = 0) -> tuple[float, float]:
        """One ``control()`` call: returns the voltages (V) for the next tick's ``io()``."""
        measured = {"a": io.speed_a_rad_s, "b": io.speed_b_rad_s}
        out = [0.0] * 8
        voltage = {"a": 0.0, "b": 0.0}
        for i, motor in enumerate(MOTORS):
            controller = self.controllers.get(motor)
            if controller is None:
                continue
            reference = self.reference_at(motor)
            voltage[motor] = controller.step(reference, measured[motor])
            out[OUT_SPEED + i] = measured[motor]
            out[OUT_VOLTAGE + i] = voltage[motor]
            out[OUT_REFERENCE + i] = reference
        self.out_floats = out
        self.tick += 1
        return voltage["a"], voltage["b"]
