"""A minimal progress bar on stderr for long runs (shown only on a terminal)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """Draws ``label [#####-----]  42 %  630/1500`` on one line of stderr, at most 10 times a
    second, and only when that is a terminal, so logs and pipes stay clean."""

    def __init__(self, total: int, label: str = "") -> None:
        self.total = max(1, total)
        self.label = label
        self.stream: TextIO = sys.stderr
        self.enabled = self.stream.isatty()
        self._last_draw = 0.0
        self._drawn = False

    def update(self, done: int) -> None:
        """Report ``done`` steps finished; redraws when 0.1 s has passed or at the end."""
        if not self.enabled:
            return
        now = time.monotonic()
        if done < self.total and now - self._last_draw < 0.1:
            return
        self._last_draw = now
        frac = min(1.0, done / self.total)
        width = 30
        filled = round(width * frac)
        self._draw(
            f"\r{self.label} [{'#' * filled}{'-' * (width - filled)}] {100 * frac:3.0f} %  {done}/{self.total}"
        )
        self._drawn = True

    def close(self) -> None:
        """End the bar's line."""
        if self.enabled and self._drawn:
            self._draw("\n")

    def _draw(self, text: str) -> None:
        """Write ``text``; a terminal gone (closed: EIO) ends the bar, never what it shows."""
        try:
            self.stream.write(text)
            self.stream.flush()
        except OSError:
            self.enabled = False
