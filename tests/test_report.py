"""Identification figures and summary (cartctl.identification.report)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cartctl.data.modelfile import load_models
from cartctl.data.trace import Trace
from cartctl.errors import InputError
from cartctl.identification.etfe import etfe
from cartctl.identification.figures import plot_etfe, plot_io, plot_pzmap, plot_step_validation
from cartctl.identification.report import ReportSection, write_summary
from cartctl.model import ArxModel
from cartctl.signals import square, step

TS = 0.01
MODELS = Path(__file__).resolve().parents[1] / "models"


@pytest.fixture(scope="module")
def models() -> dict[str, ArxModel]:
    return {
        "ground (models/ground.toml)": load_models(MODELS / "ground.toml").motor("a"),
        "air (models/air.toml)": load_models(MODELS / "air.toml").motor("a"),
        "OE, complex poles": ArxModel((-1.6, 0.68), (0.3, 0.1), nk=2),
        "zero outside": ArxModel((-0.9, 0.2), (0.2, 0.5), nk=2),
    }


@pytest.fixture(scope="module")
def trace(models: dict[str, ArxModel]) -> Trace:
    u = square(10.0, cycles=4)
    ground = next(iter(models.values()))
    y = ground.simulate(u)
    rng = np.random.default_rng(0)
    return Trace.from_columns(
        {
            "time_s": np.arange(u.size) * TS,
            "voltage_a": u,
            "voltage_b": u,
            "speed_a": y + 0.2 * rng.standard_normal(u.size),
            "speed_b": 0.9 * y,
        },
        source="synthetic.csv",
    )


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One folder for the figures several tests check: each is drawn once per module."""
    return tmp_path_factory.mktemp("report")


@pytest.fixture(scope="module")
def etfe_png(report_dir: Path, trace: Trace, models: dict[str, ArxModel]) -> tuple[Path, Path]:
    """(path asked for, path returned) of the ETFE figure with the models: checked as a PNG by
    test_plot_etfe and embedded in summary.md by test_report_end_to_end."""
    e = etfe(trace.speed_a, trace.voltage_a, TS, period_ticks=300)
    path = report_dir / "etfe_a.png"
    return path, plot_etfe(e, models, path, title="ETFE")


@pytest.fixture(scope="module")
def pzmap_png(report_dir: Path, models: dict[str, ArxModel]) -> tuple[Path, Path]:
    """(path asked for, path returned) of the pole-zero map of the models: checked as a PNG by
    test_plot_pzmap and embedded in summary.md by test_report_end_to_end."""
    path = report_dir / "pz_a.png"
    return path, plot_pzmap(models, path, title="poles and zeros")


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) in pixels, read back from the PNG."""
    import matplotlib.image

    height, width = matplotlib.image.imread(path).shape[:2]
    return width, height


def check_png(path: Path, written: Path) -> None:
    assert written == path
    assert path.stat().st_size > 10_000
    width, height = image_size(path)
    assert 700 <= width <= 1600
    assert 450 <= height <= 1100
    assert_drawn(path)


def assert_drawn(path: Path) -> None:
    """Something is drawn: a blank or nearly blank figure fails (a property of the pixels)."""
    import matplotlib.image

    pixels = matplotlib.image.imread(path)[..., :3].reshape(-1, 3)
    background = np.median(pixels, axis=0)
    inked = np.any(np.abs(pixels - background) > 0.1, axis=1).mean()
    levels = np.round(pixels * 8).astype(np.int64)  # 0..8 per channel: one int per colour
    colours = len(np.unique(levels[:, 0] * 81 + levels[:, 1] * 9 + levels[:, 2]))
    assert inked > 0.02, f"{path.name}: only {inked:.1%} of the pixels are drawn"
    assert colours >= 6, f"{path.name}: {colours} colours"


def test_a_blank_figure_fails_the_check(tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(8, 5))
    fig.savefig(tmp_path / "blank.png")
    plt.close(fig)
    with pytest.raises(AssertionError, match="drawn"):
        assert_drawn(tmp_path / "blank.png")


def test_plot_io(tmp_path: Path, trace: Trace) -> None:
    path = tmp_path / "io.png"
    check_png(path, plot_io(trace, ("a", "b"), path, title="square wave"))
    zoomed = tmp_path / "sub" / "io_zoom.png"
    check_png(zoomed, plot_io(trace, ["a"], zoomed, title="zoom", zoom_s=(3.0, 6.0)))


def test_plot_io_errors(tmp_path: Path, trace: Trace) -> None:
    with pytest.raises(InputError, match="motor"):
        plot_io(trace, ("c",), tmp_path / "x.png", title="x")
    with pytest.raises(InputError, match="at least one motor"):
        plot_io(trace, (), tmp_path / "x.png", title="x")
    with pytest.raises(InputError, match="zoom"):
        plot_io(trace, ("a",), tmp_path / "x.png", title="x", zoom_s=(5.0, 2.0))


def test_plot_etfe(tmp_path: Path, trace: Trace, etfe_png: tuple[Path, Path]) -> None:
    check_png(*etfe_png)
    e = etfe(trace.speed_a, trace.voltage_a, TS, period_ticks=300)
    bare = tmp_path / "etfe_bare.png"
    check_png(bare, plot_etfe(e, {}, bare, title="ETFE, no models"))


def test_plot_pzmap(
    tmp_path: Path, models: dict[str, ArxModel], pzmap_png: tuple[Path, Path]
) -> None:
    check_png(*pzmap_png)
    inside = {k: v for k, v in models.items() if k != "zero outside"}
    path2 = tmp_path / "pz_inside.png"
    check_png(path2, plot_pzmap(inside, path2, title="zoomed"))
    with pytest.raises(InputError, match="at least one model"):
        plot_pzmap({}, tmp_path / "none.png", title="none")


def test_plot_step_validation(tmp_path: Path, models: dict[str, ArxModel]) -> None:
    u = step(10.0, duration_s=2.0)
    t = np.arange(u.size) * TS
    measured = next(iter(models.values())).simulate(u)
    simulated = {label: m.simulate(u) for label, m in models.items()}
    path = tmp_path / "step.png"
    check_png(path, plot_step_validation(t, u, measured, simulated, path, title="step"))
    with pytest.raises(InputError, match="one value per time step"):
        plot_step_validation(t, u, measured[:-1], simulated, path, title="step")


def test_write_summary(tmp_path: Path) -> None:
    (tmp_path / "figs").mkdir()
    absolute = tmp_path / "figs" / "pz.png"
    sections = [
        ReportSection("Experiment", "Square wave, *10 V*.", images=["io.png"]),
        ReportSection(
            "Motor a",
            "Fits below.",
            images=[Path("etfe_a.png"), absolute],
            table=[
                {"model": "ARX", "c": -0.93561234, "fit %": 97.25, "note": "a|b"},
                {"model": "OE", "c": -0.91, "σ(c)": 0.0012, "nk": 2, "note": None},
            ],
        ),
        ReportSection("Empty"),
    ]
    path = write_summary(tmp_path / "out", title="Motor identification", sections=sections)
    assert path == tmp_path / "out" / "summary.md"
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# Motor identification\n")
    for heading in ("## Experiment", "## Motor a", "## Empty"):
        assert heading in text
    assert "](io.png)" in text
    assert "](etfe_a.png)" in text
    assert "](../figs/pz.png)" in text
    lines = text.splitlines()
    assert "| model | c | fit % | note | σ(c) | nk |" in lines
    assert "| ARX | -0.9356 | 97.25 | a\\|b |  |  |" in lines
    assert "| OE | -0.91 |  |  | 0.0012 | 2 |" in lines
    header = lines.index("| model | c | fit % | note | σ(c) | nk |")
    assert set(lines[header + 1].replace(" ", "")) <= set("|-")


def test_report_end_to_end(
    report_dir: Path,
    models: dict[str, ArxModel],
    etfe_png: tuple[Path, Path],
    pzmap_png: tuple[Path, Path],
) -> None:
    """The figures of one identification, embedded in summary.md, all exist (the module's
    figures, drawn once for this test and the per-plot tests above)."""
    images = [etfe_png[1], pzmap_png[1]]
    rows = [{"model": k, "DC gain": m.dc_gain()} for k, m in models.items()]
    section = ReportSection("Motor a", "text", [p.relative_to(report_dir) for p in images], rows)
    text = write_summary(report_dir, title="t", sections=[section]).read_text(encoding="utf-8")
    for image in images:
        assert f"]({image.name})" in text
        assert image.is_file()
    for label in models:
        assert f"| {label} |" in text
