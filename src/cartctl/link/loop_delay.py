"""The loop delay read from the bridge's echoes: its spread, how sure it is, and when it changes.

Each command the cart applied comes back as an echo; the ticks from the measurement it answered
to that echo are the loop delay of that command (:mod:`cartctl.link.serial_cart`). A host that
replies late now and then gives a spread of delays. Pure: counts in, verdicts out.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

MIN_ECHOES = 20
"""Echoes a measurement needs before it can be clear."""
CLEAR_SHARE = 0.85
"""Share of the echoes that must agree on one delay for the measurement to be clear (17 of 20)."""
CHANGE_SHARE = 0.05
"""During a run, more than this share of echoes at another delay than the probe's is a change."""


def _ticks(n: int) -> str:
    return f"{n} tick" + ("" if n == 1 else "s")


@dataclass(frozen=True)
class EchoDelays:
    """Echo delays counted per value: ``(delay_ticks, echoes)`` pairs by delay, echoes > 0."""

    counts: tuple[tuple[int, int], ...]

    @classmethod
    def of(cls, counts: Mapping[int, int]) -> EchoDelays:
        """From a mapping delay (ticks) → echoes (a :class:`collections.Counter`)."""
        return cls(tuple(sorted((int(d), int(n)) for d, n in counts.items() if n > 0)))

    @property
    def echoes(self) -> int:
        return sum(n for _, n in self.counts)

    @property
    def mode(self) -> int | None:
        """The most frequent delay (ticks; the shorter one on a tie), None without echoes."""
        if not self.counts:
            return None
        return max(self.counts, key=lambda pair: (pair[1], -pair[0]))[0]

    def _share(self, delay_ticks: int) -> float:
        total = self.echoes
        return 0.0 if total == 0 else dict(self.counts).get(delay_ticks, 0) / total

    @property
    def mode_share(self) -> float:
        """Share of the echoes at :attr:`mode` (0 without echoes)."""
        return 0.0 if self.mode is None else self._share(self.mode)

    def share_not(self, delay_ticks: int) -> float:
        """Share of the echoes at any other delay than ``delay_ticks`` (0 without echoes)."""
        return 0.0 if self.echoes == 0 else 1.0 - self._share(delay_ticks)

    @property
    def clear(self) -> bool:
        """At least :data:`MIN_ECHOES` echoes and :data:`CLEAR_SHARE` of them at one delay."""
        return self.echoes >= MIN_ECHOES and self.mode_share >= CLEAR_SHARE

    def describe(self) -> str:
        """``1 tick in 19 of 20 echoes (95 %), 2 ticks in 1``: the mode first, then the rest."""
        mode = self.mode
        if mode is None:
            return "no echoes"
        head = (
            f"{_ticks(mode)} in {dict(self.counts)[mode]} of {self.echoes} echoes "
            f"({100.0 * self.mode_share:.0f} %)"
        )
        return ", ".join([head, *(f"{_ticks(d)} in {n}" for d, n in self.counts if d != mode)])

    def to_dict(self) -> dict[str, Any]:
        """For ``--json``: mode, echoes, the mode's share, range, clear, counts by delay."""
        return {
            "ticks": self.mode,
            "echoes": self.echoes,
            "mode_share_percent": 100.0 * self.mode_share,
            "min": self.counts[0][0] if self.counts else None,
            "max": self.counts[-1][0] if self.counts else None,
            "clear": self.clear,
            "counts": {str(d): n for d, n in self.counts},
        }


def delay_change(probe: EchoDelays, run: EchoDelays) -> str | None:
    """How the run's echo delays differ from the probe's before it; None when they agree.

    A change is another most frequent delay than the probe's, or more than
    :data:`CHANGE_SHARE` of the run's echoes at another delay than the probe's most frequent.
    """
    expected = probe.mode
    if expected is None or run.mode is None:
        return None
    other = run.share_not(expected)
    if run.mode == expected and other <= CHANGE_SHARE:
        return None
    what = (
        "changed"
        if run.mode != expected
        else f"varied ({100.0 * other:.0f} % of the commands took another than {_ticks(expected)})"
    )
    return (
        f"the loop delay {what} during the run: {run.describe()}; the probe before it measured "
        f"{probe.describe()}"
    )
