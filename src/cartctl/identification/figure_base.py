"""The identification figures' common ground: style, resolution, a figure without pyplot, saving.

matplotlib is imported inside the functions (the package import stays light) and figures are
drawn on their own canvases, without pyplot's global state.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from matplotlib.typing import RcKeyType

__all__ = ["DPI", "color", "figure", "save"]

DPI = 110
"""Resolution of the PNG files (dots per inch); 10 × 6.5 in figures are 1100 × 715 px."""

_STYLE: dict[RcKeyType, Any] = {
    "font.size": 10,
    "axes.titlesize": 11,
    "axes.labelsize": 10,
    "legend.fontsize": 9,
    "figure.titlesize": 13,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "lines.linewidth": 1.4,
}
_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


@contextmanager
def figure(width_in: float, height_in: float) -> Iterator[Figure]:
    """A constrained-layout figure drawn under the report's style (no pyplot, nothing to close)."""
    import matplotlib as mpl
    from matplotlib.figure import Figure

    with mpl.rc_context(_STYLE):
        yield Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")


def save(fig: Figure, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    return path


def color(i: int) -> str:
    return _COLORS[i % len(_COLORS)]
