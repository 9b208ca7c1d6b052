"""``cartctl commission``: through the command line on the physics simulator (not real time), and
its pure parts against hand calculations and invariants."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.commission import checks
from cartctl.commission import checks as verify
from cartctl.data.trace import Trace
from cartctl.model import ArxModel
from cartctl.plants.physics_params import preset
from cartctl.tune import batch as timing

STAGE_FILES = ("checks", "excitation", "identification", "tuning", "verification")


def _ground_motor() -> tuple[float, float]:
    """The ground preset's steady gain K/(K² + R b) (rad/s/V) and breakaway τ_c R / K (V)."""
    p = preset("ground")
    m = p.motor_a
    k, r, b = m.torque_constant_n_m_a, m.resistance_ohm, m.viscous_n_m_s
    return k / (k * k + r * b), (m.coulomb_n_m + p.rolling_n_m) * r / k


@pytest.fixture(scope="module")
def commissioned(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, dict, object]:
    out = tmp_path_factory.mktemp("commission") / "cart"
    import contextlib
    import io

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["commission", "physics", "--out", str(out), "--json", "--jobs", "1"])
    return code, json.loads(stdout.getvalue()), out


def test_commission_physics_writes_every_file(commissioned) -> None:
    code, result, out = commissioned
    assert code == 0
    for name in ("model.toml", "controller.toml", "summary.md", "checks.csv", "excitation.csv"):
        assert (out / name).is_file(), name
    for stage in STAGE_FILES:
        assert (out / f"{stage}.rrd").stat().st_size > 0, stage
        assert f"## {stage}" in (out / "summary.md").read_text(encoding="utf-8")
    assert sorted(result["recordings"]) == sorted(str(out / f"{s}.rrd") for s in STAGE_FILES)
    text = (out / "summary.md").read_text(encoding="utf-8")
    assert "{" not in text and "}" not in text  # every figure formatted, no template left


def test_commission_recordings_hold_each_stage(commissioned, rrd_rows) -> None:
    _, _, out = commissioned
    ticks = len((out / "checks.csv").read_text().strip().splitlines()) - 1
    expected = {
        "checks": ("motor/a/speed", ticks),
        "excitation": ("motor/b/voltage", 1500),
        "identification": ("identification/a/simulated", None),
        "tuning": ("tuning/model/speed_a", 101),
        "verification": ("motor/a/speed", 201),
    }
    for stage, (entity, rows) in expected.items():
        counted = rrd_rows(out / f"{stage}.rrd")  # also: each file has its footer (closed)
        assert counted[entity] == rows if rows is not None else counted[entity] > 100, stage


def test_review_shows_what_each_stage_recorded(commissioned, tmp_path, rrd_rows, blueprint_views):
    """`cartctl review identification.rrd` (and tuning.rrd) laid the run's motor/... plots over
    a recording of other entities: every plot empty. Each scalar series recorded is in a view."""
    from rerun.chunk import RrdReader

    from cartctl.cli.commands.review.recording import layout

    _, _, out = commissioned
    for stage in ("identification", "tuning"):
        reader = RrdReader(out / f"{stage}.rrd")
        saved = tmp_path / f"{stage}.rbl"
        layout(list(reader.stream(store=reader.recordings()[0]))).save("cartctl", saved)
        views = blueprint_views(saved)
        shown = {c.replace("$origin", v["origin"]).strip("/") for v in views.values()
                 for c in v["contents"]}  # fmt: skip
        assert set(rrd_rows(out / f"{stage}.rrd")) <= shown, stage


def test_summary_tables_are_markdown_tables(commissioned) -> None:
    """Each table of summary.md has as many cells in every line as its delimiter row: a '|' in a
    cell ('max |pole|') split it, and the identification table rendered as text."""
    import re

    _, _, out = commissioned
    lines = (out / "summary.md").read_text(encoding="utf-8").splitlines()
    cells = [len(re.findall(r"(?<!\\)\|", line)) for line in lines]
    delimiters = [i for i, line in enumerate(lines) if re.fullmatch(r"\|(---\|)+", line)]
    assert len(delimiters) >= 4  # checks, identification, tuning, verification
    for i in delimiters:
        table = range(i - 1, next((j for j in range(i, len(lines)) if not lines[j]), len(lines)))
        assert {cells[j] for j in table} == {cells[i]}, lines[i - 1]


def test_commission_json_keys_and_figures(commissioned) -> None:
    _, result, out = commissioned
    assert result["model"]["path"] == str(out / "model.toml")
    assert result["controller"]["path"] == str(out / "controller.toml")
    assert result["verification"]["pass"] is True
    for m in ("a", "b"):
        model = result["model"]["motors"][m]
        assert model["validation_fit_percent"] > 90.0
        assert model["pole_radius"] < 0.99
    from cartctl.data.modelfile import load_models
    from cartctl.design.controllerfile import load_controller

    assert load_models(out / "model.toml").loop_delay_ticks == 1  # the simulator's, as checked
    assert load_controller(out / "controller.toml").loop_delay_ticks == 1
    predicted = result["controller"]["predicted"]
    assert predicted["nominal_overshoot_percent"] <= 5.0
    assert predicted["nominal_settling_time_s"] <= 0.13


def test_commission_checks_match_the_preset_by_hand(commissioned) -> None:
    _, result, _ = commissioned
    gain, breakaway = _ground_motor()
    for m in ("a", "b"):
        c = result["checks"]["motors"][m]
        assert c["direction"] == "forward"
        # the ramp sees the wheel move within a few ticks (4 V/s) of τ_c R / K
        assert breakaway - 0.05 <= c["breakaway_v"] <= breakaway + 0.25
        assert c["gain_rad_s_v"] == pytest.approx(gain, rel=0.05)
    # the model's DC gain: the preset's steady speed at the amplitude over the amplitude
    amplitude = result["excitation"]["amplitude_v"]
    steady = gain * (amplitude - breakaway)
    assert result["model"]["motors"]["a"]["dc_gain"] * amplitude == pytest.approx(steady, rel=0.03)


def test_commission_verification_matches_an_independent_run(commissioned, tmp_path, capsys) -> None:
    _, result, out = commissioned
    capsys.readouterr()
    code = main(["run", "--plant", "physics", "--controller", str(out / "controller.toml"),
                 "--fast", "--duration", "2", "--rerun", "off", "--out", str(tmp_path),
                 "--json"])  # fmt: skip
    assert code == 0
    run = json.loads(capsys.readouterr().out)
    worst_os = max(run["motors"][m]["overshoot_percent"] for m in ("a", "b"))
    worst_ts = max(run["motors"][m]["settling_time_s"] for m in ("a", "b"))
    measured = result["verification"]["measured"]
    assert measured["overshoot_percent"] == pytest.approx(worst_os, abs=1e-9)
    assert measured["settling_time_s"] == pytest.approx(worst_ts, abs=1e-9)
    assert worst_os <= 5.0 and worst_ts <= 0.15  # the acceptance figures


def test_commission_refuses_a_backwards_motor(tmp_path, capsys) -> None:
    out = tmp_path / "c"
    code = main(["commission", "physics:reverse_b=1", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) >= 1 and "motor b runs backwards" in err[-1] and "swap" in err[-1]
    assert (out / "checks.csv").is_file() and (out / "summary.md").is_file()
    assert not (out / "model.toml").exists() and not (out / "controller.toml").exists()


@pytest.mark.realtime
def test_commission_stops_when_the_loop_delay_is_not_clear(tmp_path, capsys) -> None:
    """virtual:late=0.5: stretches of commands answered a tick late, 40 % of the echoes at 2
    ticks. A controller is for one loop: commissioning stops at its checks, before driving."""
    out = tmp_path / "c"
    code = main(["commission", "virtual:late=0.5", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert "loop delay is not clear" in err[-1] and "echoes" in err[-1]
    assert not (out / "checks.csv").exists() and not (out / "model.toml").exists()


def test_commission_stops_on_a_model_that_fails_validation(tmp_path, capsys) -> None:
    out = tmp_path / "c"
    code = main(["commission", "physics", "--noise", "10", "--seed", "3", "--out", str(out),
                 "--jobs", "1"])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 1
    assert "identification" in err and "fails validation" in err and "validation fit" in err
    assert (out / "model-failed.toml").is_file() and (out / "excitation.csv").is_file()
    assert not (out / "controller.toml").exists()
    assert "**Stopped:**" in (out / "summary.md").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["commission", "sim"], "PLANT must be"),
        (["commission", "physics:reverse_c=1"], "bad physics option"),
        (["commission", "virtual:reverse_b=2"], "reverse_b"),
        (["commission", "physics", "--noise", "-1"], "--noise"),
    ],
)
def test_commission_bad_input_is_one_line(argv, words, tmp_path, capsys) -> None:
    code = main([*argv, "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0]
    assert not (tmp_path / "c").exists()


def test_a_cart_that_never_answers_is_not_said_to_have_stopped(tmp_path, capsys, monkeypatch):
    """A port where no cart talks (a cart not powered): the line says what the link found, not
    that a cart that never started 'stopped'."""
    import os

    from cartctl.link import cart_link

    monkeypatch.setattr(cart_link, "LEGACY_LISTEN_S", 0.05)  # the second listen, at 115200 baud
    master, slave = os.openpty()
    try:
        code = main(["commission", f"serial:{os.ttyname(slave)}", "--connect-timeout", "0.05",
                     "--out", str(tmp_path / "c")])  # fmt: skip
    finally:
        os.close(master)
        os.close(slave)
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 1
    assert err.startswith("cartctl commission: checks: no HEARTBEAT from a cart on"), err
    assert "stopped" not in err


class _StopAt:
    """A physics plant that raises KeyboardInterrupt (Ctrl-C) at step ``stop_at`` of its
    experiment, and remembers what it was told last."""

    made = 0

    def __init__(self, plant, stop_at: int | None) -> None:
        self.plant, self.stop_at, self.steps = plant, stop_at, 0
        self.period_s = plant.period_s
        self.loop_delay_ticks = 1
        self.closed = False

    def reset(self):
        return self.plant.reset()

    def step(self, va: float, vb: float):
        self.steps += 1
        if self.steps == self.stop_at:
            raise KeyboardInterrupt
        return self.plant.step(va, vb)

    def close(self) -> None:
        self.plant.close()
        self.closed = True


def test_ctrl_c_in_the_excitation_keeps_the_files_and_zero_volts(tmp_path, capsys, monkeypatch):
    from cartctl.commission import stages
    from cartctl.plants.factory import make_plant

    made: list[_StopAt] = []

    def make(spec, **options):
        plant, description = make_plant(spec, **options)
        made.append(_StopAt(plant, 100 if made else None))  # the second plant: the excitation
        return made[-1], description

    monkeypatch.setattr(stages, "make_plant", make)
    out = tmp_path / "c"
    code = main(["commission", "physics", "--out", str(out)])
    assert code == 130
    assert "excitation: interrupted; zero volts sent" in capsys.readouterr().err
    assert all(p.closed for p in made) and len(made) == 2
    assert made[1].plant.applied_voltage_v == (0.0, 0.0)
    rows = (out / "excitation.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 100  # the header and the 100 ticks measured before Ctrl-C
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "## checks" in summary and "## stopped" in summary
    assert "At stage **excitation**: interrupted; zero volts sent." in summary  # the stage once
    assert "**Stopped** after 100 ticks: interrupted; excitation.csv holds them." in summary
    assert "Error" not in summary  # no class name in the user's report
    assert not (out / "model.toml").exists()


def test_an_error_of_cartctls_own_in_a_stage_is_not_blamed_on_the_cart(
    tmp_path, capsys, monkeypatch
):
    """A bug of cartctl in a stage's experiment (a RuntimeError, no PlantError) read 'checks: the
    cart stopped: internal error: …'; the line and the summary say it is cartctl's, as run does."""
    from cartctl.commission import stages
    from cartctl.plants.factory import make_plant

    class Failing(_StopAt):
        def step(self, va: float, vb: float):
            if self.steps + 1 == self.stop_at:
                raise RuntimeError("a bug")
            return super().step(va, vb)

    made: list[Failing] = []

    def make(spec, **options):
        plant, description = make_plant(spec, **options)
        made.append(Failing(plant, 51))
        return made[-1], description

    monkeypatch.setattr(stages, "make_plant", make)
    out = tmp_path / "c"
    code = main(["commission", "physics", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and made[0].closed and made[0].plant.applied_voltage_v == (0.0, 0.0)
    assert err[-1] == "cartctl commission: checks: internal error: RuntimeError: a bug", err
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "At stage **checks**: internal error: RuntimeError: a bug." in summary
    assert "cart stopped" not in summary
    assert len((out / "checks.csv").read_text().strip().splitlines()) == 1 + 51  # up to step 51


# -- the pure parts --------------------------------------------------------------------------------


def _model() -> ArxModel:
    return ArxModel((-0.9, 0.2), (0.13, 0.54, -0.1), 1, 0.01)


def test_later_command_keeps_gain_and_poles() -> None:
    model = _model()
    later = timing.later_command(model, 0.4)
    assert later.dc_gain() == pytest.approx(model.dc_gain(), rel=1e-12)
    assert later.ar == model.ar and later.nk == model.nk and later.nb == model.nb + 1


def test_later_command_by_a_whole_tick_is_one_tick_of_delay() -> None:
    model = _model()
    u = np.random.default_rng(5).standard_normal(200)
    whole = timing.later_command(model, 1.0).simulate(u)
    assert np.allclose(whole, model.with_extra_delay(1).simulate(u), atol=1e-12)
    assert np.allclose(timing.later_command(model, 0.0).simulate(u), model.simulate(u))


def _trace(speed_a: np.ndarray, speed_b: np.ndarray, ua: np.ndarray, ub: np.ndarray) -> Trace:
    n = ua.size
    return Trace.from_columns({"time_s": np.arange(n) * 0.01, "voltage_a": ua, "voltage_b": ub,
                               "speed_a": speed_a, "speed_b": speed_b})  # fmt: skip


@pytest.mark.parametrize(
    ("wiring", "direction_a"),
    [("straight", "forward"), ("reversed", "backward"), ("crossed", "crossed"), ("dead", "still")],
)
def test_checks_read_the_wiring(wiring, direction_a) -> None:
    ua, ub, windows = checks.checks_sequence(0.01)
    gain, breakaway = 2.0, 1.0
    # a static motor with a one-tick lag and dead zone below the breakaway voltage
    drive = {m: np.roll(np.where(np.abs(u) > breakaway, gain * (u - breakaway), 0.0), 1)
             for m, u in (("a", ua), ("b", ub))}  # fmt: skip
    sa, sb = drive["a"], drive["b"]
    if wiring == "reversed":
        sa = -sa
    elif wiring == "crossed":
        sa, sb = sb, sa
    elif wiring == "dead":
        sa = np.zeros_like(sa)
    found = checks.analyse_checks(_trace(sa, sb, ua, ub), windows, loop_delay_ticks=0)
    assert found["a"].direction == direction_a
    if wiring == "straight":
        assert found["a"].breakaway_v == pytest.approx(breakaway, abs=0.15)  # a half count to see
        assert found["a"].gain_rad_s_v == pytest.approx(gain, rel=0.02)
        checks.verdict(found)
    else:
        with pytest.raises(checks.StageError, match="motor a"):
            checks.verdict(found)


def test_amplitude_rule_by_hand() -> None:
    def motor(breakaway: float, gain: float) -> checks.MotorCheck:
        return checks.MotorCheck("a", 1.0, 0.0, "forward", breakaway, gain)

    # report's 10 V when the speed allows it: 1 + 20 / 2 = 11 V ceiling
    assert checks.choose_amplitude({"a": motor(1.0, 2.0)}, 10.0).voltage_v == 10.0
    # a fast motor: 0.5 + 20 / 4 = 5.5 V
    assert checks.choose_amplitude({"a": motor(0.5, 4.0)}, 10.0).voltage_v == 5.5
    # much friction: at least 3 × 3 V, within 90 % of 12 V
    assert checks.choose_amplitude({"a": motor(3.0, 4.0)}, 10.0).voltage_v == 9.0
    assert checks.choose_amplitude({"a": motor(5.0, 4.0)}, 10.0).voltage_v == 10.8
    # 0.48 + 20 / 2.19 = 9.612 V: 9.6 V, and the rule says the same (it rounded to 9.6 V while
    # the amplitude was cut to 9.5 V for a ceiling of 9.5997 V)
    for gain, cut in ((2.19, 9.6), (2.2, 9.5)):  # 0.48 + 20 / 2.2 = 9.5709 V
        amplitude = checks.choose_amplitude({"a": motor(0.48, gain)}, 10.0)
        assert amplitude.voltage_v == cut and f"at most {cut:.1f} V" in amplitude.rule


@pytest.mark.parametrize(
    ("speed", "overshoot", "settling", "passed"),
    [("true_speed", 5.9, 0.149, True), ("true_speed", 6.1, 0.1, False),
     ("speed", 8.4, 0.1, True), ("speed", 8.6, 0.1, False), ("true_speed", 1.0, None, False),
     ("true_speed", 1.0, 0.151, False)],
)  # fmt: skip
def test_verification_bounds(speed, overshoot, settling, passed) -> None:
    figures = {"overshoot_percent": overshoot, "settling_time_s": settling}
    summary = {"metrics_signal": speed, "motors": {m: dict(figures) for m in ("a", "b")}}
    predicted = {"nominal_overshoot_percent": 0.5, "nominal_settling_time_s": 0.12}
    result = verify.compare(summary, predicted)
    assert result.passed is passed
    quantum = 100.0 * 2.0 * math.pi / 1792 / 0.01 / 10.0  # one count per tick over 10 rad/s
    assert result.limits["overshoot_percent"] == pytest.approx(
        5.0 + (1.0 if speed == "true_speed" else quantum)
    )


def test_verification_takes_the_smoothed_speed_over_the_encoder() -> None:
    quantum = 100.0 * 2.0 * math.pi / 1792 / 0.01 / 10.0
    smoothed = {"overshoot_percent": 2.0, "settling_time_s": 0.12}
    motor = {"overshoot_percent": 5.2, "settling_time_s": 0.185}
    summary = {"metrics_signal": "speed", "motors": {"a": motor, "b": motor}}
    result = verify.compare(summary, {"nominal_overshoot_percent": 0.5},
                            {"a": smoothed, "b": smoothed})  # fmt: skip
    assert result.passed and result.measured == smoothed and result.limits["speed"] == "smoothed"
    assert result.limits["overshoot_percent"] == pytest.approx(5.0 + 1.0 + quantum / 2)


def test_an_unstable_model_fails_validation_in_words() -> None:
    """An unstable model's simulation fit is −inf (identification.arx.simulation_fit); the verdict
    says the simulation diverges rather than printing "-inf %"."""
    from types import SimpleNamespace

    from cartctl.identification.arx import simulation_fit

    model = ArxModel.from_theta([-1.05, 0.0, 0.1, 0.0])  # a pole at 1.05
    fit = simulation_fit(model, [(np.ones(200), np.ones(200))])
    residuals = SimpleNamespace(cross=np.zeros(5), cross_bound_99=1.0, cross_outside=0, white=True)
    motor = SimpleNamespace(
        chosen=SimpleNamespace(fit_simulation_percent=fit, model=model),
        diagnostics=SimpleNamespace(residuals=residuals),
    )
    (verdict,) = checks.judge(SimpleNamespace(motors={"a": motor})).values()  # type: ignore[arg-type]
    assert verdict.problems[0] == (
        f"validation fit: the simulation diverges (needs >= {checks.MIN_FIT_PERCENT:g} %)"
    )
    assert "inf" not in " ".join(verdict.problems)


def test_a_verification_that_never_settles_says_so(tmp_path) -> None:
    """A step that is still outside its band when the run ends: the stage's line and summary.md
    say 'not settled' (JSON: null, as run's), not 'settling — ms'; the line names only the bound
    missed."""
    from types import SimpleNamespace

    from cartctl.commission import StageError, stages

    figures = {"overshoot_percent": 0.0, "settling_time_s": None}
    summary = {"metrics_signal": "true_speed", "motors": {m: dict(figures) for m in "ab"},
               "trace": str(tmp_path / "verification.csv"), "recording": None}  # fmt: skip
    job = stages.Commission("physics", tmp_path, dict.fromkeys(stages.PLANT_FLAGS.values()),
                            lambda argv: (0, summary))  # fmt: skip
    predicted = {"nominal_overshoot_percent": 0.1, "nominal_settling_time_s": 0.12}
    job.tuned = SimpleNamespace(predicted=lambda: predicted)
    with pytest.raises(StageError) as failed:
        job.run_verification()
    line = str(failed.value)
    assert "not settled" in line and "—" not in line and "overshoot" not in line
    assert job.results["verification"]["measured"]["settling_time_s"] is None
    table = (tmp_path / "summary.md").read_text(encoding="utf-8")
    assert "| settling (ms) | not settled |" in table
