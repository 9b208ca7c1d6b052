"""``cartctl tune``'s printed output, through the CLI: distinct column names with units, settings
counted by what happened to them, the plot's front non-dominated in its own axes, its numbers
not overlapping, one rounding per column.

The expectations are computed here from the ``--json`` rows (numpy dominance checks, counts from
``feasible`` and ``settling_time_s``) and from the figure ``--plot`` saves (captured at
``savefig``: the ringed and plotted points, the labels' boxes from the Agg renderer).
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text

from cartctl.cli import main
from cartctl.measures.numfmt import SIG_FIGS

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
# 60° and 65° at 2 Hz need Kp < 0 on the ground model; at 0.6 s (10 ticks after the step) the
# 65° / 4 Hz design settles (about 69 ms), the 60° / 4 Hz one (about 126 ms) does not
SMALL = ("--method", "pi", "--grid", "phase_margin=60:65:5,crossover_hz=2:4:2", "--duration", "0.6")
DEFAULT = ("--method", "pi", "--duration", "1")  # the default 7 × 6 PI grid


def _cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _table(out: str) -> tuple[list[str], list[dict[str, str]]]:
    """The table's headers and rows (cells by header): 'front' is the first 5 characters."""
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if re.match(r"front +#  ", line))
    headers = ["front", *re.split(r"\s{2,}", lines[head][7:].strip())]
    rows = []
    for line in lines[head + 1 :]:
        if not line[5:9].strip().isdigit():
            break
        cells = [line[:5].strip(), *re.split(r"\s{2,}", line[7:].strip())]
        assert len(cells) == len(headers), line
        rows.append(dict(zip(headers, cells, strict=True)))
    return headers, rows


def _significant(cell: str) -> int:
    """Significant digits of a printed number: leading zeros never count, an integer's trailing
    zeros do not either (1230 has three)."""
    digits = cell.lstrip("-")
    if "." not in digits:
        digits = digits.rstrip("0") or "0"
    return len(digits.replace(".", "").lstrip("0"))


def _dominated(points: np.ndarray, p: np.ndarray) -> bool:
    return bool(np.any(np.all(points <= p, axis=1) & np.any(points < p, axis=1)))


@pytest.fixture(scope="module")
def default_grid(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The default PI grid: --json with --plot (the figure captured at savefig), then the text."""
    tmp = tmp_path_factory.mktemp("tune_output")
    figures: list[Figure] = []
    original = Figure.savefig

    def keep(self: Figure, *args: Any, **kwargs: Any) -> None:
        figures.append(self)
        original(self, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Figure, "savefig", keep)
        code, out, err = _cli("tune", str(GROUND), *DEFAULT, "--jobs", "2", "--plot",
                              str(tmp / "t.png"), "--json")  # fmt: skip
    assert code == 0, err
    code, text, err = _cli("tune", str(GROUND), *DEFAULT, "--jobs", "2")
    assert code == 0, err
    return {"doc": json.loads(out), "figure": figures[0], "text": text}


def test_the_ringed_points_are_the_front_of_the_plotted_axes(default_grid: dict[str, Any]) -> None:
    fig = default_grid["figure"]
    ax = fig.axes[0]
    plotted = next(c for c in ax.collections if c.get_gid() == "settings").get_offsets()
    ringed = next(c for c in ax.collections if c.get_gid() == "front").get_offsets()
    plotted, ringed = np.asarray(plotted, float), np.asarray(ringed, float)
    assert len(ringed) >= 2
    for p in ringed:  # none is dominated in the plot's own axes
        assert not _dominated(plotted, p), p
    for p in plotted:  # and every point not ringed is dominated by a ringed one
        if not any(np.array_equal(p, q) for q in ringed):
            assert _dominated(ringed, p), p
    # the JSON's pareto_plot rows, at their exact (settling ms, overshoot %)
    rows = default_grid["doc"]["settings"]
    marked = {
        (r["settling_time_s"] * 1e3, r["overshoot_percent"]) for r in rows if r["pareto_plot"]
    }
    assert marked == {tuple(p) for p in ringed}
    # the four-metric front is another set: it has points the two axes show as dominated
    assert sum(r["pareto"] for r in rows) > sum(r["pareto_plot"] for r in rows)
    assert default_grid["doc"]["pareto_plot_of"] == ["settling_time_s", "overshoot_percent"]


def test_the_front_numbers_overlap_nothing_and_all_text_is_inside_the_figure(
    default_grid: dict[str, Any],
) -> None:
    fig = default_grid["figure"]
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    boxes = [Text.get_window_extent(t, renderer) for t in ax.texts]  # the text, not its line
    labels = sorted(int(t.get_text()) for t in ax.texts)
    ringed = sorted(r["index"] for r in default_grid["doc"]["settings"] if r["pareto_plot"])
    assert labels == ringed  # every ringed point numbered with its setting #
    for i, a in enumerate(boxes):
        assert ax.get_window_extent(renderer).contains(a.x0, a.y0)
        assert ax.get_window_extent(renderer).contains(a.x1, a.y1)
        for b in boxes[i + 1 :]:
            assert not a.overlaps(b), (a, b)
    frame = fig.bbox
    for text in fig.findobj(Text):
        if text.get_visible() and text.get_text().strip():
            box = text.get_window_extent(renderer)
            assert frame.x0 - 1 <= box.x0 and box.x1 <= frame.x1 + 1, text.get_text()
            assert frame.y0 - 1 <= box.y0 and box.y1 <= frame.y1 + 1, text.get_text()


def test_crowded_labels_are_placed_apart_or_named_as_unplaced() -> None:
    """40 points of a staircase packed into a corner: each number is placed where it overlaps no
    other number and no point, or reported back as left without a place."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from cartctl.tune.plot import place_labels

    fig = Figure(figsize=(8, 6), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    x = np.linspace(50, 60, 40)
    y = np.linspace(5, 0, 40)
    ax.scatter(x, y)
    ax.set_xlim(0, 200)
    ax.set_ylim(-1, 20)
    left = place_labels(fig, ax, [(a, b, str(i)) for i, (a, b) in enumerate(zip(x, y, strict=True))],
                        [(a, b, 3.0) for a, b in zip(x, y, strict=True)])  # fmt: skip
    fig.draw_without_rendering()  # the layout and text extents of a draw, without the pixels
    renderer = fig.canvas.get_renderer()
    placed = [t.get_text() for t in ax.texts]
    assert sorted(placed + left, key=int) == [str(i) for i in range(40)] and placed
    boxes = [Text.get_window_extent(t, renderer) for t in ax.texts]  # the text, not its line
    for i, a in enumerate(boxes):
        for b in boxes[i + 1 :]:
            assert not a.overlaps(b)
        centres = ax.transData.transform(np.column_stack([x, y]))
        assert not any(a.contains(cx, cy) for cx, cy in centres)


def test_the_marks_of_the_table_are_the_two_fronts(default_grid: dict[str, Any]) -> None:
    _, rows = _table(default_grid["text"])
    assert len(rows) == 42
    doc = {r["index"]: r for r in default_grid["doc"]["settings"]}
    assert {int(r["#"]) for r in rows if "*" in r["front"]} == {i for i, r in doc.items() if r["pareto"]}  # fmt: skip
    assert {int(r["#"]) for r in rows if "o" in r["front"]} == {i for i, r in doc.items() if r["pareto_plot"]}  # fmt: skip
    # the 'o' rows are non-dominated in (settling, overshoot) among the settled: checked by numpy
    settled = np.array([[r["settling_time_s"], r["overshoot_percent"]] for r in doc.values()
                        if r["settling_time_s"] is not None])  # fmt: skip
    for r in rows:
        exact = doc[int(r["#"])]
        p = np.array([np.inf if exact[k] is None else exact[k]
                      for k in ("settling_time_s", "overshoot_percent")])  # fmt: skip
        assert ("o" in r["front"]) == (np.isfinite(p).all() and not _dominated(settled, p))


def test_every_column_says_what_and_its_unit_and_has_one_rounding(
    default_grid: dict[str, Any],
) -> None:
    headers, rows = _table(default_grid["text"])
    named = [h for h in headers if h not in ("front", "#", "status")]
    assert all(re.search(r"\((%|ms|s|deg|Hz|rad/s|V)\)$", h) for h in named), named
    assert all(h.startswith(("design ", "run ")) for h in named)
    doc = {r["index"]: r for r in default_grid["doc"]["settings"]}
    keys = {"run overshoot (%)": ("overshoot_percent", 1.0),
            "run settling (ms)": ("settling_time_s", 1e3),
            "run rms error (rad/s)": ("rms_error", 1.0),
            "run peak |V| (V)": ("peak_voltage_v", 1.0)}  # fmt: skip
    for head, (key, factor) in keys.items():
        cells = [(r[head], doc[int(r["#"])][key]) for r in rows if r[head] != "—"]
        decimals = {len(c.partition(".")[2]) for c, _ in cells}
        assert len(decimals) == 1, (head, decimals)  # one precision per column
        assert max(_significant(c) for c, _ in cells) <= SIG_FIGS, head
        step = 10.0 ** -decimals.pop()
        for cell, exact in cells:  # each the exact value, rounded
            assert abs(float(cell) - exact * factor) <= step / 2 + 1e-9, (head, cell, exact)


def test_poles_asked_and_run_overshoot_are_two_columns_with_distinct_names() -> None:
    code, out, err = _cli("tune", str(GROUND), "--method", "poles", "--grid",
                          "settling_time=0.06:0.08:0.02,overshoot=1:2:1", "--duration", "1",
                          "--jobs", "1")  # fmt: skip
    assert code == 0, err
    headers, rows = _table(out)
    assert len(headers) == len(set(headers))
    assert "design overshoot (%)" in headers and "run overshoot (%)" in headers
    assert {r["design overshoot (%)"] for r in rows} == {"1", "2"}  # as asked, exact


def test_settings_are_counted_by_what_happened_to_them() -> None:
    code, out, err = _cli("tune", str(GROUND), *SMALL, "--jobs", "1", "--json")
    assert code == 0, err
    doc = json.loads(out)
    rows = doc["settings"]
    infeasible = sum(not r["feasible"] for r in rows)
    unsettled = sum(r["feasible"] and r["settling_time_s"] is None for r in rows)
    settled = sum(r["settling_time_s"] is not None for r in rows)
    assert (infeasible, unsettled, settled) == (2, 1, 1)  # the three kinds, on this grid
    assert doc["counts"] == {"settings": 4, "infeasible": 2, "run_failed": 0, "no_step": 0,
                             "not_settled": 1, "settled": 1, "pareto": 1, "pareto_plot": 1}  # fmt: skip
    code, text, err = _cli("tune", str(GROUND), *SMALL, "--jobs", "1")
    assert code == 0, err
    assert text.splitlines()[0].endswith(
        ": 4 settings: 2 infeasible requests (the design refused them), 1 ran but did not "
        "settle, 1 settled"
    )
    _, table = _table(text)
    expected = {r["index"]: "infeasible" if not r["feasible"] else
                "not settled" if r["settling_time_s"] is None else "settled" for r in rows}  # fmt: skip
    assert {int(r["#"]): r["status"] for r in table} == expected
    assert {r["index"]: r["status"] for r in rows} == expected


def test_choose_best_without_a_settled_setting_prints_the_table_then_one_line(
    tmp_path: Path,
) -> None:
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid",
                          "phase_margin=60:65:5,crossover_hz=2:4:2", "--duration", "0.56",
                          "--jobs", "1", "--choose", "best", "--out", str(tmp_path / "c.toml"))  # fmt: skip
    assert code == 2
    assert "2 ran but did not settle, 0 settled" in out and len(_table(out)[1]) == 4
    assert err.count("\n") == 1 and "--choose best: no feasible setting settles" in err
    assert not (tmp_path / "c.toml").exists()


def test_choose_on_an_infeasible_row_with_json_prints_the_json_then_one_line(
    tmp_path: Path,
) -> None:
    code, out, err = _cli("tune", str(GROUND), *SMALL, "--jobs", "1", "--choose", "3", "--out",
                          str(tmp_path / "c.toml"), "--json")  # fmt: skip
    assert code == 2
    doc = json.loads(out)
    assert doc["chosen"] is None and len(doc["settings"]) == 4
    choosable = sorted(r["index"] for r in doc["settings"] if r["feasible"])
    assert err.count("\n") == 1
    assert err.rstrip().endswith(f"settings that can be chosen: {', '.join(map(str, choosable))}")


def _captured_plot(monkeypatch: pytest.MonkeyPatch, *argv: str) -> tuple[dict[str, Any], Figure]:
    figures: list[Figure] = []
    original = Figure.savefig

    def keep(self: Figure, *args: Any, **kwargs: Any) -> None:
        figures.append(self)
        original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    code, out, err = _cli(*argv)
    assert code == 0, err
    return json.loads(out), figures[0]


def test_robust_plot_front_labels_and_counts(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    doc, fig = _captured_plot(monkeypatch, "tune", str(GROUND), "--method", "pi", "--grid",
                              "phase_margin=60:75:5,crossover_hz=3:5:1", "--robust", "--plants",
                              "8", "--duration", "1", "--jobs", "1", "--plot",
                              str(tmp_path / "r.png"), "--json")  # fmt: skip
    ax = fig.axes[0]
    plotted = np.asarray(next(c for c in ax.collections if c.get_gid() == "settings").get_offsets())
    ringed = np.asarray(next(c for c in ax.collections if c.get_gid() == "front").get_offsets())
    for p in ringed:  # nominal settling (ms) against worst-case overshoot (%): the plotted axes
        assert not _dominated(plotted, p)
    rows = doc["settings"]
    expected = {(r["robust"]["nominal"]["settling_time_s"] * 1e3, r["robust"]["worst"]["overshoot_percent"])
                for r in rows if r["robust"] is not None and r["robust"]["pareto"]}  # fmt: skip
    assert expected == {tuple(p) for p in ringed}
    renderer = fig.canvas.get_renderer()
    boxes = [Text.get_window_extent(t, renderer) for t in ax.texts]
    assert sorted(int(t.get_text()) for t in ax.texts) == sorted(
        r["index"] for r in rows if r["robust"] is not None and r["robust"]["pareto"]
    )
    for i, a in enumerate(boxes):
        assert all(not a.overlaps(b) for b in boxes[i + 1 :])
    for text in fig.findobj(Text):
        if text.get_visible() and text.get_text().strip():
            box = text.get_window_extent(renderer)
            assert fig.bbox.x0 - 1 <= box.x0 and box.x1 <= fig.bbox.x1 + 1, text.get_text()
            assert fig.bbox.y0 - 1 <= box.y0 and box.y1 <= fig.bbox.y1 + 1, text.get_text()
    # the counts, recounted from the rows
    robust = [r["robust"] for r in rows]
    everywhere = sum(r is not None and r["settles_on_every_plant"] for r in robust)
    nominal_settled = sum(r["settling_time_s"] is not None for r in rows)
    assert doc["robust"]["counts"] == {
        "infeasible": sum(not r["feasible"] for r in rows), "run_failed": 0, "no_step": 0,
        "not_settled": sum(r["feasible"] and r["settling_time_s"] is None for r in rows),
        "settled_on_some": nominal_settled - everywhere, "settled_on_all": everywhere,
    }  # fmt: skip


def test_a_reference_without_a_step_is_said_so_not_called_unsettled() -> None:
    """A ramp has no step: overshoot and settling are undefined, not 'did not settle'."""
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid",
                          "phase_margin=65,crossover_hz=3:4:1", "--duration", "1", "--jobs", "1",
                          "--reference", "ramp:10", "--json")  # fmt: skip
    assert code == 0, err
    rows = json.loads(out)["settings"]
    assert all(r["feasible"] and r["overshoot_percent"] is None for r in rows)
    assert {r["status"] for r in rows} == {"no step"}
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid",
                          "phase_margin=65,crossover_hz=3:4:1", "--duration", "1", "--jobs", "1",
                          "--reference", "ramp:10")  # fmt: skip
    assert code == 0, err
    assert out.splitlines()[0].endswith(
        "2 settings: 0 infeasible requests (the design refused them), 2 ran without a step in "
        "the reference to measure, 0 ran but did not settle, 0 settled"
    )


def test_choose_out_designs_for_the_step_tuned_on(tmp_path: Path) -> None:
    """A model that reaches 9.7 rad/s at 12 V, tuned on step:5: the settings ran and settled,
    but --out designed the file for design's default 10 rad/s step and refused it ('a 10 rad/s
    step cannot be held within ±12 V', exit 2, no file). The file is now for the 5 rad/s step,
    and its analysis's step is the chosen row's run (motor a)."""
    model = tmp_path / "weak.toml"
    motor = "theta = [-0.9356, 0.2173, 0.25864, -0.031004]\nna = 2\nnb = 2\nnk = 2\n"
    model.write_text(
        'format = "cartctl-model/2"\nperiod_s = 0.01\nloop_delay_ticks = 1\n\n[provenance]\n'
        'source = "t"\ncreated = "2026-01-01"\ndata = []\nmethod = "arx"\nprefilter = "none"\n'
        f'notes = ""\n\n[motors.a]\n{motor}\n[motors.b]\n{motor}'
    )
    out = tmp_path / "c.toml"
    code, text, err = _cli("tune", str(model), "--method", "poles", "--grid",
                           "settling-time=0.1,overshoot=1", "--reference", "step:5", "--jobs", "1",
                           "--choose", "1", "--out", str(out), "--json")  # fmt: skip
    assert code == 0, err
    row = json.loads(text)["settings"][0]["motors"]["a"]
    doc = tomllib.loads(out.read_text())
    assert "--step 5" in doc["command"]
    step = doc["motors"]["a"]["analysis"]["step"]
    assert step["step_rad_s"] == 5.0
    assert step["overshoot_percent"] == pytest.approx(row["overshoot_percent"], rel=1e-9)
    assert step["settling_time_s"] == pytest.approx(row["settling_time_s"], rel=1e-9)
