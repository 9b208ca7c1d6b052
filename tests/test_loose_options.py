"""Options that change nothing, and option texts that parse loosely: each is one line, exit 2.

Found by the bug hunt of issue 25: ``--seed`` without noise on a simulated plant (the same run
for every seed), and the refusal of a plant option on ``commission`` naming ``--plant``, an
option commission does not have (its plant is the positional PLANT).
"""

from __future__ import annotations

from pathlib import Path

import pytest

import cartctl
from cartctl.cli import main
from cartctl.errors import CartctlError


def _line(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    """The one error line of a refused command line (exit 2, nothing on stdout)."""
    try:
        code = main(list(argv))
    except SystemExit as exc:  # argparse's own refusals
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    assert (code, out, len(err.splitlines())) == (2, "", 1), err
    return err.strip()


SEED_OFF = "--seed seeds the measurement noise, which is off; {} uses it for nothing else"


@pytest.mark.parametrize(
    ("argv", "plant"),
    [
        (("run", "--plant", "physics", "--seed", "3", "--fast"), "--plant physics"),
        (("run", "--seed", "0", "--noise", "0", "--fast"), "--plant sim"),
        (("excite", "--plant", "physics:actuation_ms=4", "--seed", "3", "--amplitude", "5",
          "--out", "x.csv"), "--plant physics:actuation_ms=4"),
        (("commission", "physics", "--seed", "3"), "PLANT physics"),
    ],
)  # fmt: skip
def test_a_seed_without_noise_on_a_simulated_plant_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: tuple[str, ...], plant: str
) -> None:
    # the run was the same for every seed: physics and sim use the seed for the noise alone
    assert SEED_OFF.format(plant) in _line(capsys, *argv)
    assert not (workdir / "x.csv").exists() and not (workdir / "logs").exists()


def test_a_seed_without_noise_is_refused_by_the_api_too(workdir: Path) -> None:
    for call in (cartctl.excite, lambda **kw: cartctl.simulate("controllers/pi.toml", **kw)):
        with pytest.raises(CartctlError, match=SEED_OFF.format("--plant physics")):
            call(plant="physics", seed=3)
    result = cartctl.simulate("controllers/pi.toml", plant="physics", seed=3,
                              noise_std_rad_s=0.2, duration_s=0.2)  # fmt: skip
    assert result.failure is None and result.columns["time_s"].size > 0


def test_commission_names_its_plant_as_the_user_gave_it(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    # the line said "--plant physics does not use it": commission has no --plant
    line = _line(capsys, "commission", "physics", "--connect-timeout", "3")
    assert line.endswith("--connect-timeout is for the virtual and serial plants; "
                         "PLANT physics does not use it")  # fmt: skip


@pytest.mark.parametrize(
    ("argv", "says"),
    [  # the last one won, silently
        (("run", "--plant", "physics:actuation_ms=3,actuation_ms=4", "--fast"),
         "physics option actuation_ms is given twice; give it once"),
        (("run", "--plant", "physics:reverse_b=1,reverse_b=0", "--fast"),
         "physics option reverse_b is given twice"),
        (("commission", "physics:actuation_ms=3,actuation_ms=4"),
         "physics option actuation_ms is given twice"),
        (("virtual-cart", "--faults", "garbage=0.1,garbage=0.2", "--duration", "0.1"),
         "virtual cart option 'garbage' is given twice; give it once"),
        (("run", "--plant", "virtual:late=0.1,late=0.3"), "virtual cart option 'late' is given"),
        (("identify", "models/ground.toml", "--orders", "na=1:3,na=2"),
         "--orders: na is given twice; give each of na, nb, nk once"),
    ],
)  # fmt: skip
def test_a_key_given_twice_in_one_option_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: tuple[str, ...], says: str
) -> None:
    assert says in _line(capsys, *argv)


QRC6 = Path(__file__).parent / "data" / "qrc6_sample.csv"


def test_one_channel_mapped_to_two_quantities_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    # speed_a was a copy of the voltage: a map's typo, taken silently
    line = _line(capsys, "convert", str(QRC6), "--map", "voltage_a=voltA,speed_a=voltA")
    assert line.endswith("the mapping gives 'voltA' to both voltage_a and speed_a; "
                         "map each to its own channel")  # fmt: skip
    with pytest.raises(CartctlError, match="gives 'speedA' to both speed_a and raw"):
        cartctl.load_trace(QRC6, map={"voltage_a": "voltA", "speed_a": "speedA", "raw": "speedA"})
    # one reference channel for both motors is one quantity: it stays allowed
    both = "voltage_a=voltA,speed_a=speedA,reference_a=FloatIn10,reference_b=FloatIn10"
    assert main(["convert", str(QRC6), "--map", both, "--out", "both.csv"]) == 0
    capsys.readouterr()
    trace = cartctl.load_trace("both.csv")
    assert trace.columns()["reference_b"].tolist() == trace.columns()["reference_a"].tolist()


@pytest.mark.parametrize("option", ["--reference", "--reference-b"])
def test_a_step_before_the_run_starts_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path, option: str
) -> None:
    # step:10:-1 ran as step:10:0, a delay the run cannot have
    line = _line(capsys, "run", option, "step:10:-1", "--fast")
    assert line.endswith(
        f"{option}: reference 'step:10:-1': the step's delay must be >= 0 s, got -1"
    )
    with pytest.raises(CartctlError, match=r"the step.s delay must be >= 0 s, got -0\.5"):
        cartctl.simulate("controllers/pi.toml", reference="step:3:-0.5")


def test_the_deadbeat_limit_names_the_option_on_the_command_line(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    # design said 'settling_time_s must be at least …', the API's name, not the option's
    line = _line(capsys, "design", "models/ground.toml", "--method", "poles", "--settling-time",
                 "0.02")  # fmt: skip
    assert line == ("cartctl design: error: --settling-time must be at least 3 ticks (0.03 s), "
                    "the deadbeat time of a loop with 3 poles; got 0.02")  # fmt: skip
    with pytest.raises(CartctlError, match=r"^settling_time_s must be at least 3 ticks"):
        cartctl.design_poles("models/ground.toml", settling_time_s=0.02, overshoot_percent=5)


@pytest.mark.parametrize(
    ("argv", "step"),
    [
        (("run", "--reference", "step:10:6"), "'step:10:6': the step at 6 s"),
        (("run", "--reference", "step:10:5"), "'step:10:5': the step at 5 s"),  # at the end
        (("run", "--reference-b", "step:10:7"), "'step:10:7': the step at 7 s"),
    ],
)
def test_a_step_after_the_run_ends_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: tuple[str, ...], step: str
) -> None:
    # it never acted: the summary was all '—', exit 0 (a delay the run cannot reach)
    line = _line(capsys, *argv, "--fast", "--duration", "5", "--rerun", "off")
    assert line.endswith(
        f"{argv[1]}: reference {step} comes after the run's last tick (4.99 s); give a delay "
        "within the run or a longer duration"
    )
    assert not Path("logs").exists()  # refused before anything was written


def test_a_step_after_the_run_ends_is_refused_by_simulate_and_tune(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    with pytest.raises(CartctlError, match=r"the step at 2 s comes after the run's last tick"):
        cartctl.simulate("controllers/pi.toml", reference="step:3:2")  # 2 s by default
    line = _line(
        capsys,
        "tune",
        "models/ground.toml",
        "--method",
        "pi",
        "--reference",
        "step:10:3",
        "--grid",
        "crossover-hz=4",
        "--jobs",
        "1",
    )
    assert line.endswith(
        "'step:10:3': the step at 3 s comes after the run's last tick (1.99 s); "
        "give a delay within the run or a longer duration"
    )
    # the last tick still steps (and an earlier run's summary has figures)
    run = cartctl.simulate("controllers/pi.toml", reference="step:3:1.99")
    assert run.summary["motors"]["a"]["max_abs_voltage"] > 0.0


@pytest.mark.parametrize("command", ["virtual-cart", "monitor virtual --rerun off"])
def test_an_onboard_step_after_the_run_ends_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path, command: str
) -> None:
    argv = [*command.split(), "--onboard", "controllers/pi.toml", "--reference", "step:10:3"]
    line = _line(capsys, *argv, "--duration", "2")
    assert line.endswith(
        "'step:10:3': the step at 3 s comes after the run's last tick (1.99 s); "
        "give a delay within the run or a longer duration"
    )


def test_an_onboard_step_within_a_duration_between_ticks_is_recorded(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    """monitor records while the cart's time is below --duration: 0.104 s holds the frame at
    0.10 s, where a step at 0.1 s acts; it was refused as after the last tick (0.09 s)."""
    argv = ["monitor", "virtual", "--rerun", "off", "--onboard", "controllers/pi.toml"]
    code = main([*argv, "--reference", "step:8:0.1", "--duration", "0.104", "--name", "x"])
    assert code == 0, capsys.readouterr().err
    header, *_, last = Path("logs/x.csv").read_text(encoding="utf-8").splitlines()
    assert float(last.split(",")[header.split(",").index("reference_a")]) == 8.0  # at 0.10 s
