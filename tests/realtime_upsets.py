"""What a busy machine did to a real-time run, read from its summary's ``link``."""

from __future__ import annotations

from typing import Any


def link_upsets(link: dict[str, Any], loop_delay_ticks: int = 1) -> int:
    """Ticks at which the host was held up: watchdog trips, ticks the host missed or skipped,
    and echoes later than the loop delay. A real-time test asks for a clean step only when there
    were none; otherwise for the speed to come back (the summary has said what happened)."""
    upsets = sum(int(link[key]) for key in ("watchdog_trips", "missed_ticks", "skipped_ticks"))
    seen = link.get("loop_delay_ticks_seen") or {}
    return upsets + sum(n for ticks, n in seen.items() if int(ticks) != loop_delay_ticks)
