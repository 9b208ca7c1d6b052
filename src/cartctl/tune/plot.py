"""``cartctl tune --plot``: settling time against overshoot, the front ringed and numbered.

The ringed points are the front over the two plotted metrics (plain: ``pareto_plot``;
``--robust``: the robust front), so none is dominated in the plot's own axes. Each carries its
setting number where it overlaps no other label, point or ring (:func:`place_labels`); one left
without room is named in a note under the axes, beside the legend."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from cartctl.data.outputs import writing
from cartctl.tune.grid import TuneResult
from cartctl.tune.robust import RobustRow

RING_AREA_PT2 = 150.0  # marker areas (pt²)
POINT_AREA_PT2 = 36.0
TITLE_CHARS = 100  # 9-point text across the axes of the 8-inch figure

_DISTANCES_PT = (7, 12, 18, 26, 36, 48, 62, 76, 90)
_ANGLES_DEG = (45, -45, 135, -135, 90, -90, 0, 180, 20, -20, 160, -160, 65, -65, 115, -115)


def _figure(*title: str) -> tuple[Any, Any]:
    """A figure and its axes, titled with ``title``'s parts in lines of :data:`TITLE_CHARS`."""
    import textwrap

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 6.4), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.set_ylabel("run overshoot (%)")
    ax.grid(True, color="0.9")
    lines = [line for part in title for line in textwrap.wrap(part, TITLE_CHARS)]
    ax.set_title("\n".join(lines), fontsize=9)
    return fig, ax


def _hits_circle(box: Any, cx: float, cy: float, r: float) -> bool:
    nx = min(max(cx, box.x0), box.x1)
    ny = min(max(cy, box.y0), box.y1)
    return math.hypot(nx - cx, ny - cy) < r


def place_labels(
    fig: Any,
    ax: Any,
    points: Sequence[tuple[float, float, str]],
    obstacles: Sequence[tuple[float, float, float]],
    color: str = "tab:red",
) -> list[str]:
    """Annotate each point (x, y, text; data coordinates) where its text overlaps nothing, and
    return the texts left without a place. Candidates are offsets of 7 to 90 pt in 16 directions,
    the first free one taken (with a thin line when 18 pt or more away): inside the axes, clear of
    the labels placed so far and of the ``obstacles`` (x, y, radius in pt). Lays the figure out once
    (a draw without rendering) to fix its layout."""
    from matplotlib.transforms import Bbox

    fig.draw_without_rendering()  # the layout a draw gives, without its pixels
    renderer = fig.canvas.get_renderer()
    px_per_pt = fig.dpi / 72.0
    frame = ax.get_window_extent(renderer)
    circles = [(*ax.transData.transform((x, y)), r * px_per_pt) for x, y, r in obstacles]
    taken: list[Any] = []
    left: list[str] = []
    for x, y, text in sorted(points):
        probe = ax.text(0.0, 0.0, text, fontsize=9)
        size = probe.get_window_extent(renderer)
        probe.remove()
        w, h = size.width + 2.0, size.height + 2.0  # a pixel of margin all round
        px, py = ax.transData.transform((x, y))
        for dist, angle in ((d, a) for d in _DISTANCES_PT for a in _ANGLES_DEG):
            dx = dist * math.cos(math.radians(angle))
            dy = dist * math.sin(math.radians(angle))
            ox = px + dx * px_per_pt - (0.0 if dx > 0.5 else w if dx < -0.5 else w / 2)
            oy = py + dy * px_per_pt - (0.0 if dy > 0.5 else h if dy < -0.5 else h / 2)
            box = Bbox.from_bounds(ox - 1.0, oy - 1.0, w, h)
            if (frame.contains(box.x0, box.y0) and frame.contains(box.x1, box.y1)
                    and not any(box.overlaps(b) for b in taken)
                    and not any(_hits_circle(box, *c) for c in circles)):  # fmt: skip
                break
        else:  # no free place
            left.append(text)
            continue
        taken.append(box)
        ha = "left" if dx > 0.5 else "right" if dx < -0.5 else "center"
        va = "bottom" if dy > 0.5 else "top" if dy < -0.5 else "center"
        arrow = {"arrowstyle": "-", "color": color, "lw": 0.6} if dist >= 18 else None
        note = ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points", ha=ha,
                           va=va, color=color, fontsize=9, arrowprops=arrow)  # fmt: skip
        note.set_in_layout(False)
    return left


def _unplaced_note(texts: Sequence[str]) -> str:
    return f"ringed without a number (no room for it): #{', #'.join(sorted(texts, key=int))}"


def _finish(fig: Any, ax: Any, front: Sequence[tuple[float, float, int]],
            everything: Sequence[tuple[float, float]], path: str, notes: Sequence[str]) -> None:  # fmt: skip
    """Ring and number the front, put the legend and notes under the axes, and save. The labels are
    placed once the legend is in place (it moves the axes). When some find no room, a legend line
    names them and they are placed again (the new line moves the axes once more); its text then
    lists the final ones, so the layout holds."""
    if front:
        ax.scatter([x for x, _, _ in front], [y for _, y, _ in front], s=RING_AREA_PT2,
                   facecolors="none", edgecolors="tab:red", linewidths=1.5, zorder=4,
                   gid="front", label="ringed, with its #: on the front of the two plotted "
                   "metrics")  # fmt: skip
    for note in notes:  # legend entries without a marker
        ax.plot([], [], " ", label=note)
    fig.legend(loc="outside lower center", ncols=1, fontsize=8)
    obstacles = [(x, y, math.sqrt(POINT_AREA_PT2) / 2.0) for x, y in everything]
    obstacles += [(x, y, math.sqrt(RING_AREA_PT2) / 2.0) for x, y, _ in front]
    labels = [(x, y, str(i)) for x, y, i in front]
    unplaced = place_labels(fig, ax, labels, obstacles)
    if unplaced:
        for artist in [*ax.texts, *fig.legends]:
            artist.remove()
        ax.plot([], [], " ", label=_unplaced_note(unplaced))
        legend = fig.legend(loc="outside lower center", ncols=1, fontsize=8)
        unplaced = place_labels(fig, ax, labels, obstacles)
        legend.get_texts()[-1].set_text(_unplaced_note(unplaced) if unplaced
                                        else "every ringed point has its #")  # fmt: skip
    with writing(path):
        fig.savefig(path)


def plot_tuning(path: str, method: str, results: Sequence[TuneResult]) -> None:
    """Run settling (ms) against run overshoot (%) of the settled settings (colour: peak |V|)."""
    from cartctl.tune.choice import counts_text

    settled = [
        (r, r.worst["settling_time_s"], r.worst["overshoot_percent"])
        for r in results
        if r.status == "settled"
    ]
    shown = [(r, s * 1e3, o) for r, s, o in settled if s is not None and o is not None]  # ms, %
    x, y = [s for _, s, _ in shown], [o for _, _, o in shown]
    title = f"cartctl tune --method {method}, the worse of motors a and b"
    fig, ax = _figure(title, counts_text(results))
    points = ax.scatter(x, y, c=[r.worst["max_abs_voltage"] for r, _, _ in shown], cmap="viridis",
                        s=POINT_AREA_PT2, zorder=3, gid="settings",
                        label="settings that settled (colour: run peak |V|)")  # fmt: skip
    fig.colorbar(points, ax=ax, label="run peak |voltage| (V)")
    front = [(xi, yi, r.index) for r, xi, yi in shown if r.pareto_plot]
    ax.set_xlabel("run settling time, band max(2 %, one encoder count) (ms)")
    notes = ["the table's *: the front over all four run metrics (RMS error and peak |V| too), "
             "which may hold points not ringed here"]  # fmt: skip
    _finish(fig, ax, front, list(zip(x, y, strict=True)), path, notes)


def plot_robust(path: str, method: str, rows: Sequence[RobustRow], plants: int) -> None:
    """Nominal settling (ms) against overshoot (%): worst case (colour: p95 settling), nominal
    (grey, joined to it) and physics (x)."""
    import numpy as np
    from matplotlib import colormaps

    from cartctl.tune.choice import robust_counts_text

    scored = [(*r.score.front_axes, r.score, r) for r in rows if r.score is not None]
    shown = [(x * 1e3, y, s, r) for x, y, s, r in scored if np.isfinite(x) and np.isfinite(y)]
    timed = ", ".join(f"{e['actuation_ms']:g}" for e in shown[0][2].actuation) if shown else ""
    title = (
        f"cartctl tune --method {method} --robust, the worse of motors a and b; ringed: the "
        "front of nominal settling against worst-case overshoot"
    )
    fig, ax = _figure(title, robust_counts_text(rows))
    for x, y, s, _ in shown:
        ax.plot([x, x], [s.value("overshoot_percent", "nominal"), y], color="0.8", lw=1, zorder=1)
    xs = [x for x, *_ in shown]
    p95 = [s.value("settling_time_s", "p95") * 1e3 for *_, s, _ in shown]
    worst = ax.scatter(xs, [y for _, y, *_ in shown], s=POINT_AREA_PT2, zorder=3, gid="settings",
                       plotnonfinite=True, cmap=colormaps["viridis"].with_extremes(bad="black"),
                       c=[v if np.isfinite(v) else np.nan for v in p95],
                       label=f"worst case over the model and {plants} sampled plants"
                             + (f" and physics at {timed} ms" if timed else ""))  # fmt: skip
    fig.colorbar(worst, ax=ax, label="settling time, p95 of the plants (ms); "
                 "black: > 5 % never settle")  # fmt: skip
    nominal = [(x, s.value("overshoot_percent", "nominal")) for x, _, s, _ in shown]
    ax.scatter([x for x, _ in nominal], [v for _, v in nominal], s=12, color="0.5", zorder=2,
               label="nominal (the model)")  # fmt: skip
    physics = [(x, s.physics.get("overshoot_percent")) for x, _, s, _ in shown]
    phys = [(x, v) for x, v in physics if v is not None]
    ax.scatter([x for x, _ in phys], [v for _, v in phys], marker="x", color="tab:orange", s=30,
               zorder=2, label=f"physics preset {shown[0][2].physics.get('preset') if shown else ''}")  # fmt: skip
    front = sorted((x, y, r.index) for x, y, _, r in shown if r.pareto)
    ax.set_xlabel("nominal settling time, band max(2 %, one encoder count) (ms)")
    everything = [(x, y) for x, y, *_ in shown] + nominal + phys
    _finish(fig, ax, front, everything, path, [])
