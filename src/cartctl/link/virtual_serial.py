"""``--plant virtual``: the virtual cart in this process, driven through the serial path.

:class:`VirtualSerialCart` is the host side (:class:`~cartctl.link.serial_cart.SerialCart`,
unchanged) on the pseudo-terminal of a :class:`~cartctl.link.virtual_cart.VirtualCart`, plus
the one thing only a simulator knows: the true speed at each cart tick, for the trace.
"""

from __future__ import annotations

import math
import time
from typing import Any

from cartctl.link.serial_cart import SerialCart
from cartctl.link.virtual_cart import SILENCE_TIMEOUT_S, VirtualCart
from cartctl.plants.base import Measurement


class VirtualSerialCart(SerialCart):
    """``--plant virtual``: a :class:`VirtualCart` in this process, driven through the serial path.

    The cart boots once :meth:`connect` has opened the port, and is switched off on
    :meth:`close`, after it has taken the host's drive = 0 frames (so a test can check what it
    was left applying).
    """

    reports_true_speed = True
    """The simulator behind the line knows the true speeds: the trace gets them too."""

    def __init__(self, cart: VirtualCart, **kwargs: Any) -> None:
        kwargs.setdefault("silence_timeout_s", SILENCE_TIMEOUT_S)
        super().__init__(cart.port, **kwargs)
        self.cart = cart

    def _port_opened(self) -> None:
        """Boot the cart once the port is open (opening a real cart's port resets it, too)."""
        if self.cart.state == "idle":
            self.cart.start()

    def _with_true_speed(self, measured: Measurement) -> Measurement:
        """The measurement with the simulator's true speeds at the same cart tick (rad/s)."""
        assert self.sample is not None
        true_a, true_b = self.cart.true_speeds.get(self.sample.cart_tick, (math.nan, math.nan))
        return Measurement(measured.speed_a_rad_s, measured.speed_b_rad_s, true_a, true_b)

    def reset(self) -> Measurement:
        """As :meth:`SerialCart.reset`, with the true speed: the simulator knows it."""
        return self._with_true_speed(super().reset())

    def receive(self) -> Measurement:
        """As :meth:`SerialCart.receive`, with the true speed: the simulator knows it."""
        return self._with_true_speed(super().receive())

    def close(self) -> None:
        was_connected = self.connected and not self.link.failure
        super().close()
        if was_connected:  # let the stop frames cross the line and reach control()
            deadline = time.perf_counter() + 0.2
            while self.cart.firmware.in_ints[1] != 0 and time.perf_counter() < deadline:
                time.sleep(0.005)
            self.cart.wait_ticks(2)
        self.cart.stop()
