"""Names that say what they are: the contracts are named where they are defined and cited by name.

The four contracts other tools rely on (trace columns, command line, ``--json`` keys, Rerun entity
paths) are defined in ``docs/architecture.md`` under stable anchors; the code cites them by what
they are, never by a number that is defined nowhere.
"""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path

import control
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.design.controllerfile import load_controller, loop_site
from cartctl.plants.factory import plant_kind

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
CONTRACT_ANCHORS = ("trace-columns", "command-line", "json-output", "rerun-entities")


def test_no_module_cites_a_contract_by_number() -> None:
    numbered = re.compile(r"contract[ -]?[1-4]", re.I)
    found = [
        f"{path.relative_to(ROOT)}:{n}"
        for path in sorted((ROOT / "src" / "cartctl").rglob("*.py"))
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if numbered.search(line)
    ]
    assert not found, found


def test_each_contract_has_a_heading_with_a_stable_anchor() -> None:
    text = ARCHITECTURE.read_text(encoding="utf-8")
    anchors = re.findall(r"^#+ .*\{#([\w-]+)\}\s*$", text, flags=re.M)
    assert set(CONTRACT_ANCHORS) <= set(anchors)


def test_the_contracts_name_what_the_code_keeps() -> None:
    """The defined columns and entity paths are the ones the code writes (a typo in either fails)."""
    from cartctl.data.trace import REQUIRED_COLUMNS
    from cartctl.sinks.base import TRACE_COLUMNS, TRUE_SPEED_COLUMNS
    from cartctl.sinks.rerun_layout import ENTITY_PATHS

    text = ARCHITECTURE.read_text(encoding="utf-8")
    section = text.split("{#trace-columns}", 1)[1].split("{#command-line}", 1)[0]
    for column in (*REQUIRED_COLUMNS, *TRACE_COLUMNS, *TRUE_SPEED_COLUMNS):
        assert f"`{column}`" in section, column
    rerun = text.split("{#rerun-entities}", 1)[1]
    for column in ("reference_a", "speed_a", "estimate_a", "voltage_a", "compute_us"):
        assert f"`{ENTITY_PATHS[column]}`" in rerun, column


def test_measurement_noise_the_option_is_the_extra_and_the_file_holds_the_total(
    tmp_path: Path,
) -> None:
    """``--measurement-noise`` is the noise on top of the encoder's quantisation; the estimator's
    ``measurement_noise_std_rad_s`` is the total √R = √(q²/6 + extra²), q = 2π/1792 rad per 10 ms
    (one encoder count per tick)."""
    quantum_rad_s = 2.0 * math.pi / 1792 / 0.01  # by hand: 1792 counts per revolution
    for extra in (0.0, 0.2):
        out = tmp_path / f"poles-{extra}.toml"
        argv = ["design", "models/ground.toml", "--method", "poles", "--out", str(out)]
        assert main([*argv, "--measurement-noise", str(extra)]) == 0
        doc = tomllib.loads(out.read_text(encoding="utf-8"))
        assert doc["request"]["extra_noise_std_rad_s"] == extra
        total = doc["motors"]["a"]["estimator"]["measurement_noise_std_rad_s"]
        assert math.isclose(total, math.hypot(quantum_rad_s / math.sqrt(6.0), extra))


def test_the_help_of_measurement_noise_says_extra_and_names_the_total(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    start = help_text.rindex("--measurement-noise RAD_S")  # its entry, after the usage
    entry = help_text[start : start + 220]
    assert "extra" in entry and "quantisation" in entry and "measurement_noise_std_rad_s" in entry


def test_plant_kind_in_a_controller_file_is_where_the_loop_runs() -> None:
    """The file's ``plant_kind`` follows from its loop delay (``loop_site``): 'onboard' for the
    shipped on-board files, 'serial' for the serial ones; it is never a ``--plant`` name."""
    for name in ("pi", "poles", "serial-pi", "serial-poles"):
        path = ROOT / "controllers" / f"{name}.toml"
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
        loaded = load_controller(path)
        expected = "serial" if name.startswith("serial") else "onboard"
        assert raw["plant_kind"] == loaded.loop_site == expected
        assert loop_site(raw["loop_delay_ticks"]) == expected
    assert loop_site(1) == "onboard" and loop_site(3) == "serial"
    assert plant_kind("serial:/dev/ttyACM0") == "serial" and plant_kind("sim") == "sim"


def test_arx_model_b_holds_the_reports_a_and_b_and_ar_its_c_and_d() -> None:
    """``ArxModel.b`` is B(q), the numerator: the report's (a, b); ``ar`` is (c, d). Checked on
    the shipped ground model (the report's equation 12) against python-control, evaluating the
    report's (a z + b) / (z³ + c z² + d z) by hand at a point."""
    c, d, a, b = -0.9356, 0.2173, 0.6466, -0.07751  # the report's θ for motor A, on the ground
    model = load_models("models/ground.toml").motor("a")
    assert model.ar == (c, d) and model.b == (a, b)
    assert list(model.theta) == [c, d, a, b]
    system = control.tf(model.num(), model.den(), model.period_s)
    z = 0.3 + 0.4j
    assert complex(system(z)) == pytest.approx((a * z + b) / (z**3 + c * z**2 + d * z))
