"""A designed controller running on the (virtual) cart itself, as the exported C does.

:class:`OnboardFirmware` is the Python twin of ``cartctl export --arduino``'s ``control()``, for
the virtual cart (``cartctl virtual-cart --onboard``, ``cartctl monitor virtual --onboard``): per
tick and motor u = controller.step(r, measured speed), applied at the next ``io()`` (one tick of
delay, as on the real cart). The channels are :mod:`cartctl.link.firmware_id`'s layout 1. The
references come from a reference spec (tick 0 at the first ``control()``) or else from the held
input channels. The controllers run the fixed Kalman gain, as the C does; the template's
``controlEnabled()`` (QRC button 0) is not modelled.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Protocol

from cartctl.cart import PERIOD_S
from cartctl.choices import MAX_DURATION_S
from cartctl.errors import InputError
from cartctl.link.bridge_firmware import CartIO, HeldChannels
from cartctl.link.firmware_id import (
    CH_FIRMWARE_ID,
    IN_REFERENCE,
    ONBOARD_ID,
    OUT_REFERENCE,
    OUT_SPEED,
    OUT_VOLTAGE,
)
from cartctl.reference import ReferenceSchedule

MOTORS = tuple(IN_REFERENCE)
MAX_TICKS = round(MAX_DURATION_S / PERIOD_S)
"""A reference spec is evaluated over the longest run cartctl takes (24 h), then held."""


class _Controller(Protocol):
    def reset(self) -> None: ...
    def step(self, reference_rad_s: float, measured_rad_s: float) -> float: ...


class OnboardFirmware(HeldChannels):
    """``control()`` running a runtime controller per motor ('a', 'b'; none: 0 V) on the cart.

    ``reference`` is the reference spec of both motors (None: the held input channels),
    ``period_s`` the tick the controllers were designed for.
    """

    ready_text = "cartctl on-board controller ready"

    def __init__(
        self,
        controllers: Mapping[str, _Controller],
        *,
        reference: str | None = None,
        period_s: float = PERIOD_S,
    ) -> None:
        unknown = sorted(set(controllers) - set(MOTORS))
        if unknown:
            raise InputError(f"the cart has motors a and b, not {', '.join(unknown)}")
        self.controllers = dict(controllers)
        self._schedules: dict[str, ReferenceSchedule] = {}
        if reference is not None:  # else the held input channels
            self._schedules = {
                m: ReferenceSchedule(reference, MAX_TICKS, float(period_s), m) for m in controllers
            }
        self.reset()

    def reset(self) -> None:
        """Power-on state: channels 0, controllers at rest, tick 0."""
        self.reset_channels()
        for controller in self.controllers.values():
            controller.reset()

    def receive(self, floats: Sequence[float], ints: Sequence[int], now_ms: int = 0) -> None:
        self.hold(floats, ints)

    def reference_at(self, motor: str) -> float:
        """The reference (rad/s) of ``motor`` at the current tick."""
        if self._schedules:
            return self._schedules[motor][min(self.tick, MAX_TICKS - 1)]
        return self.in_floats[IN_REFERENCE[motor]]

    def control(self, io: CartIO, now_ms: int = 0) -> tuple[float, float]:
        """One ``control()`` call: returns the voltages (V) for the next tick's ``io()``."""
        measured = {"a": io.speed_a_rad_s, "b": io.speed_b_rad_s}
        out = [0.0] * 8
        out[CH_FIRMWARE_ID] = float(ONBOARD_ID)
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
