"""Reassembly of the firmware's text lines from PRINT fragments."""

from __future__ import annotations

__all__ = ["LineAssembler"]


class LineAssembler:
    """Joins PRINT texts into lines.

    The firmware ends lines with "\\r\\n" and splits text over 32-byte PRINT frames regardless of
    line boundaries. A line ends at "\\n" (with or without a "\\r" before it); a "\\r" anywhere is
    dropped, so a "\\r\\n" split over two frames still ends exactly one line.
    """

    def __init__(self) -> None:
        self._partial: list[str] = []

    def feed(self, text: str) -> list[str]:
        """Add a fragment; return the lines it completes, without their line endings.

        Parameters
        ----------
        text
            The text of one PRINT frame (or any fragment of the stream).

        Returns
        -------
        list[str]
            Completed lines, oldest first; the unfinished rest is kept for the next call.
        """
        pieces = text.replace("\r", "").split("\n")
        if len(pieces) == 1:
            if pieces[0]:
                self._partial.append(pieces[0])
            return []
        lines = ["".join([*self._partial, pieces[0]]), *pieces[1:-1]]
        self._partial = [pieces[-1]] if pieces[-1] else []
        return lines

    def flush(self) -> str | None:
        """Return and clear the unfinished line, or None if there is none."""
        partial = "".join(self._partial)
        self._partial = []
        return partial or None
