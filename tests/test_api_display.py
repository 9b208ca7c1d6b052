"""The Python API's results in a notebook: short summaries for print() and Jupyter, and plot()
figures with a title, units and a legend on every axes, without the stop row."""

from __future__ import annotations

import html
import re
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import pytest

import cartctl
from cartctl.design.controllerfile import load_controller

matplotlib.use("Agg")
ROOT = Path(__file__).resolve().parents[1]
LIMIT = 2_000  # characters: a summary, not a dump


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Every kind of result the API returns, built through the API on shipped files."""
    folder = tmp_path_factory.mktemp("api")
    trace = cartctl.excite(plant="physics", signal="square", amplitude_v=10, cycles=2)
    ident = cartctl.identify(trace)
    oe = cartctl.identify(trace, method="oe", delay="auto", motors=("a",))
    model_path = ident.save(folder / "mine.toml")
    pi = cartctl.design_pi(model_path, phase_margin_deg=65, crossover_hz=4)
    poles = cartctl.design_poles(ROOT / "models" / "ground.toml", settling_time_s=0.045)
    return {
        "trace": trace,
        "identification": ident,
        "identification (OE, one motor)": oe,
        "motor result": ident["a"],
        "model file": cartctl.load_model(ROOT / "models" / "ground.toml"),
        "design (pi)": pi,
        "design (poles)": poles,
        "controller file (designed)": pi.controller_file(),
        "controller file (serial-poles.toml)": load_controller(
            ROOT / "controllers" / "serial-poles.toml"
        ),
        "run (pi, physics)": cartctl.simulate(pi, plant="physics", duration_s=1.5),
        "run (poles.toml, sim)": cartctl.simulate(
            ROOT / "controllers" / "poles.toml", plant="sim", reference="square:8:1", duration_s=2.0
        ),
    }


KINDS = ["trace", "identification", "identification (OE, one motor)", "motor result",
         "model file", "design (pi)", "design (poles)", "controller file (designed)",
         "controller file (serial-poles.toml)", "run (pi, physics)",
         "run (poles.toml, sim)"]  # fmt: skip
SHOWN = [
    k for k in KINDS if not k.startswith(("trace", "model file", "controller file"))
]  # the API's own result classes


@pytest.mark.parametrize("kind", KINDS)
def test_repr_is_a_short_summary(results: dict[str, Any], kind: str) -> None:
    text = repr(results[kind])
    assert len(text) < LIMIT, text
    assert str(results[kind]) == text or len(str(results[kind])) < LIMIT


@pytest.mark.parametrize("kind", SHOWN)
def test_jupyter_shows_a_short_table_with_the_same_title(
    results: dict[str, Any], kind: str
) -> None:
    shown = results[kind]._repr_html_()
    assert len(shown) < 2 * LIMIT and shown.count("<tr>") <= 3  # the header and a row per motor
    title = repr(results[kind]).splitlines()[0]
    assert html.escape(title) in shown


def test_identification_summary_holds_theta_and_the_fits(results: dict[str, Any]) -> None:
    ident = results["identification"]
    lines = repr(ident).splitlines()
    assert len(lines) <= 6 and lines[0].startswith("Identification: ARX")
    for motor in "ab":
        (row,) = [line for line in lines if line.split()[:1] == [motor]]
        cells = [float(x) for x in re.findall(r"-?\d+\.?\d*(?:e-?\d+)?", row)]
        # θ's four numbers to 4 significant figures, then the fits (%) within rounding
        np.testing.assert_allclose(cells[1:5], ident[motor].theta, rtol=1e-3)
        assert any(abs(c - ident[motor].fit_simulation_percent) < 0.01 for c in cells)


def test_run_summary_holds_the_metrics_of_run_json(results: dict[str, Any]) -> None:
    run = results["run (pi, physics)"]
    text = repr(run)
    assert "plant physics" in text and "step:10" in text and "151 ticks" in text
    for motor in "ab":
        (row,) = [line for line in text.splitlines() if line.split()[:1] == [motor]]
        overshoot, settling = (float(x) for x in row.split()[1:3])
        m = run.summary["motors"][motor]
        assert overshoot == pytest.approx(m["overshoot_percent"], rel=5e-3, abs=5e-3)
        assert settling == pytest.approx(m["settling_time_s"], rel=5e-3)


def test_design_summary_holds_the_gains_and_margins(results: dict[str, Any]) -> None:
    design = results["design (pi)"]
    text = repr(design)
    assert text.startswith("Design: PI on") and "--crossover-hz 4" in text
    row = next(line for line in text.splitlines() if line.split()[:1] == ["a"])
    kp = float(re.search(r"kp (\S+),", row).group(1))  # type: ignore[union-attr]
    assert kp == pytest.approx(design["a"]["kp"], rel=1e-3)
    assert " 65 " in row  # the phase margin asked for (°)


def _figure_checks(fig: Any, motors: str) -> None:
    title = fig._suptitle.get_text() if fig._suptitle is not None else ""
    assert "plant" in title and "reference" in title
    axes = fig.get_axes()
    assert len(axes) == 2 * len(motors)
    for ax in axes:
        assert ax.get_legend() is not None, ax.get_ylabel()
        assert re.search(r"\((rad/s|V)\)", ax.get_ylabel())
    assert {ax.get_title() for ax in axes if ax.get_title()} == {f"motor {m}" for m in motors}
    assert all(ax.get_xlabel() == "time (s)" for ax in axes if "V" in ax.get_ylabel())


@pytest.mark.parametrize("motor", ["both", "a", "b"])
def test_plot_has_a_title_units_and_a_legend_on_every_axes(
    results: dict[str, Any], motor: str
) -> None:
    import matplotlib.pyplot as plt

    run = results["run (pi, physics)"]
    fig = run.plot() if motor == "both" else run.plot(motor)
    try:
        _figure_checks(fig, "ab" if motor == "both" else motor)
    finally:
        plt.close(fig)


def test_plot_leaves_out_the_stop_row(results: dict[str, Any]) -> None:
    """The last row is the zero-volt stop command; the run never commanded 0 V at its end."""
    import matplotlib.pyplot as plt

    run = results["run (poles.toml, sim)"]
    c = run.columns
    assert c["voltage_a"][-1] == 0.0 and abs(c["voltage_a"][-2]) > 0.5  # the stop row, and before
    fig = run.plot("a")
    try:
        speed_axes, voltage_axes = fig.get_axes()
        (line,) = voltage_axes.get_lines()
        n = len(c["time_s"]) - 1
        np.testing.assert_array_equal(line.get_xdata(), c["time_s"][:n])
        np.testing.assert_array_equal(line.get_ydata(), c["voltage_a"][:n])
        assert all(len(trace.get_xdata()) == n for trace in speed_axes.get_lines())
    finally:
        plt.close(fig)


def test_plot_draws_into_given_axes(results: dict[str, Any]) -> None:
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1)
    try:
        assert results["run (pi, physics)"].plot("b", ax=(top, bottom)) is fig
        assert top.get_legend() is not None and bottom.get_legend() is not None
        with pytest.raises(cartctl.errors.InputError, match="motor"):
            results["run (pi, physics)"].plot("c")
    finally:
        plt.close(fig)


def _listed(text: str, name: str) -> list[float]:
    found = re.search(rf"{name} \[([^\]]*)\]", text)
    assert found, text
    return [float(v) for v in found.group(1).split(",")]


def test_file_summaries_hold_the_gains_and_theta(results: dict[str, Any]) -> None:
    controller = results["controller file (serial-poles.toml)"]
    lines = repr(controller).splitlines()
    assert len(lines) == 3 and "loop delay 3 ticks" in lines[0] and "poles" in lines[0]
    for motor, line in zip("ab", lines[1:], strict=True):
        np.testing.assert_allclose(_listed(line, "K"), controller.motors[motor]["K"], rtol=1e-3)
    models = results["model file"]
    lines = repr(models).splitlines()
    assert len(lines) == 3 and str(ROOT / "models" / "ground.toml") in lines[0]
    for motor, line in zip("ab", lines[1:], strict=True):
        np.testing.assert_allclose(_listed(line, "θ ="), models.motor(motor).theta, rtol=1e-3)


def test_plot_refuses_axes_it_cannot_draw_in(results: dict[str, Any]) -> None:
    """Axes for both motors, one Axes or three raised ValueError or TypeError (no len())."""
    from matplotlib.figure import Figure

    top, bottom = Figure().subplots(2)
    run = results["run (pi, physics)"]
    for motor, ax in (("both", (top, bottom)), ("a", top), ("a", (top, bottom, top))):
        with pytest.raises(cartctl.errors.InputError, match=r"^axes: give \(speed_axes"):
            run.plot(motor, ax=ax)
    assert run.plot("a", ax=np.array([top, bottom])) is top.figure  # as plt.subplots(2) gives
