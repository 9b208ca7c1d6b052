"""What a busy machine did to a real-time run, read from its summary's ``link``; and the serial
plant a test builds on a virtual cart of its own process, which a busy machine holds up."""

from __future__ import annotations

from typing import Any

from cartctl.link.serial_cart import SerialCart
from cartctl.link.virtual_cart import SILENCE_TIMEOUT_S


class InProcessCart(SerialCart):
    """``serial:PORT`` on a :class:`~cartctl.link.virtual_cart.VirtualCart` of this process: silent
    after the virtual cart's 0.5 s, as ``--plant virtual`` waits, not a real cart's 0.1 s. The cart
    is threads of this process, not the loop's SCHED_FIFO one: on a busy machine they were held up
    past 0.1 s (1 run in 30 with a core busy: 'no data from the cart ... for 100 ms'), and a plant
    that gave up before an injected pull or stall never saw it."""

    def __init__(self, port: str, **options: Any) -> None:
        super().__init__(port, silence_timeout_s=SILENCE_TIMEOUT_S, **options)


def link_upsets(link: dict[str, Any], loop_delay_ticks: int = 1) -> int:
    """Ticks at which the host was held up: watchdog trips, ticks the host missed or skipped,
    and echoes later than the loop delay. A real-time test asks for a clean step only when there
    were none; otherwise for the speed to come back (the summary has said what happened)."""
    upsets = sum(int(link[key]) for key in ("watchdog_trips", "missed_ticks", "skipped_ticks"))
    seen = link.get("loop_delay_ticks_seen") or {}
    return upsets + sum(n for ticks, n in seen.items() if int(ticks) != loop_delay_ticks)
