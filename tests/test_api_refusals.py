"""``cartctl.simulate`` refuses what ``cartctl run --fast`` refuses, with the same line: both start
from :func:`cartctl.session.prepare.prepare_run`. Each case runs the command line first and then
the API on the same files; the line must be one and the same, and say the thing that is wrong."""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import cartctl
from cartctl.choices import FORMS
from cartctl.cli import main
from cartctl.design.controllerfile import load_controller
from cartctl.errors import CartctlError

_DURATION = "--duration must be a positive number of seconds up to 86400 (24 h)"


def _run_line(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    code = main(["run", "--fast", "--rerun", "off", *argv])
    _, err = capsys.readouterr()
    assert code == 2, err
    (line,) = [x for x in err.splitlines() if x.startswith("cartctl run: error: ")]
    return line.removeprefix("cartctl run: error: ")


def _simulate_line(controller: str, **options: object) -> str:
    with pytest.raises(CartctlError) as refused:
        cartctl.simulate(controller, **options)  # type: ignore[arg-type]
    return str(refused.value)


def test_a_controller_for_another_loop_delay(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    # serial-pi.toml is designed for the serial loop's 3 ticks; the physics cart has 1
    line = _run_line(capsys, "--plant", "physics", "--controller", "controllers/serial-pi.toml")
    assert "designed for a loop delay of 3" in line and "has 1" in line
    assert _simulate_line("controllers/serial-pi.toml", plant="physics") == line


def test_a_reference_no_motor_can_follow(capsys: pytest.CaptureFixture[str], workdir: Path) -> None:
    # the report's ground model reaches about 2 rad/s per volt: 12 V gives about 24 rad/s
    line = _run_line(capsys, "--controller", "controllers/pi.toml", "--reference", "step:100")
    assert "give a reference within that" in line
    assert _simulate_line("controllers/pi.toml", reference="step:100") == line


def test_an_unstable_model_on_the_sim_plant(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    text = (workdir / "models" / "ground.toml").read_text(encoding="utf-8")
    # motor a: z² − 2.1 z + 1.05 has roots 1.05 ± 0.224j, |z| ≈ 1.07: outside the unit circle
    assert "[-0.9356, 0.2173," in text
    unstable = workdir / "models" / "unstable.toml"
    unstable.write_text(text.replace("[-0.9356, 0.2173,", "[-2.1, 1.05,"), encoding="utf-8")
    line = _run_line(capsys, "--model", str(unstable), "--controller", "controllers/pi.toml")
    assert "unstable" in line and str(unstable) in line
    assert _simulate_line("controllers/pi.toml", model=str(unstable)) == line


def test_a_controller_for_another_tick(capsys: pytest.CaptureFixture[str], workdir: Path) -> None:
    # the shipped ground model at Ts = 20 ms gives a controller that no 10 ms plant may run
    text = (workdir / "models" / "ground.toml").read_text(encoding="utf-8")
    assert "\nperiod_s = 0.01\n" in text
    slow = workdir / "models" / "slow.toml"
    slow.write_text(text.replace("\nperiod_s = 0.01\n", "\nperiod_s = 0.02\n"), encoding="utf-8")
    assert main(["design", str(slow), "--method", "pi", "--out", "slow-pi.toml"]) == 0
    capsys.readouterr()
    for plant, model in (
        ("sim", {"model": "models/ground.toml"}),
        ("physics", {}),
    ):  # --model: sim's
        argv = [a for k, v in model.items() for a in (f"--{k}", v)]
        line = _run_line(capsys, "--plant", plant, *argv, "--controller", "slow-pi.toml")
        assert "designed for Ts = 0.02 s" in line and "ticks every 0.01 s" in line
        assert _simulate_line("slow-pi.toml", plant=plant, **model) == line


@pytest.mark.parametrize("duration", ["-1", "0", "nan", "1e9"])
def test_a_duration_out_of_range(
    capsys: pytest.CaptureFixture[str], workdir: Path, duration: str
) -> None:
    # simulate once ran 2 ticks for -1 s and raised numpy's ValueError for NaN
    line = _run_line(capsys, "--duration", duration)
    assert line.startswith("--duration must be a positive number of seconds")
    assert _simulate_line("controllers/pi.toml", duration_s=float(duration)) == line


@pytest.mark.parametrize(
    ("plant", "option", "value", "line"),
    [  # physics runs its preset, sim its models: the other given was silently ignored
        ("physics", "model", "models/air.toml",
         "--model is for the sim plant; --plant physics does not use it"),
        ("sim", "preset", "air",
         "--preset is for the physics and virtual plants; --plant sim does not use it"),
    ],
)  # fmt: skip
def test_a_plant_option_for_a_plant_that_has_none(
    capsys: pytest.CaptureFixture[str], workdir: Path, plant: str, option: str, value: str,
    line: str,
) -> None:  # fmt: skip
    assert _run_line(capsys, "--plant", plant, f"--{option}", value) == line
    assert _simulate_line("controllers/pi.toml", plant=plant, **{option: value}) == line


def _excite_line(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    code = main(["excite", "--amplitude", "10", "--out", "x.csv", *argv])
    _, err = capsys.readouterr()
    assert code == 2, err
    return err.strip().removeprefix("cartctl excite: error: ")


@pytest.mark.parametrize(
    ("argv", "options"),
    [
        (
            ["--plant", "physics", "--model", "models/air.toml"],
            {"plant": "physics", "model": "models/air.toml"},
        ),
        (["--plant", "sim", "--preset", "air"], {"plant": "sim", "preset": "air"}),
        (["--signal", "step", "--duration", "0"], {"signal": "step", "duration_s": 0.0}),
        (["--signal", "step", "--duration", "1e9"], {"signal": "step", "duration_s": 1e9}),
    ],
)
def test_excite_refuses_what_the_command_refuses(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: list[str], options: dict[str, object]
) -> None:
    # cartctl.excite ignored a model for physics and a preset for sim, ran 0 s and tried to
    # allocate 10¹¹ samples for 10⁹ s
    line = _excite_line(capsys, *argv)
    with pytest.raises(CartctlError) as refused:
        cartctl.excite(**options)  # type: ignore[arg-type]
    assert str(refused.value) == line
    assert not Path("x.csv").exists()


@pytest.mark.parametrize(
    ("options", "line"),
    [
        ({"zero_phase": True}, "zero_phase needs prefilter_hz"),
        ({"prefilter_order": 4}, "prefilter_order needs prefilter_hz"),
        (
            {"prefilter_order": 4, "zero_phase": True},
            "prefilter_order and zero_phase need prefilter_hz",
        ),
    ],
)
def test_identify_refuses_a_prefilter_shape_without_a_prefilter(
    capsys: pytest.CaptureFixture[str], workdir: Path, options: dict[str, object], line: str
) -> None:
    # the fit ran unfiltered, the options silently ignored (cartctl identify refuses them)
    trace = cartctl.excite(plant="physics", cycles=2)
    with pytest.raises(CartctlError) as refused:
        cartctl.identify(trace, **options)  # type: ignore[arg-type]
    assert str(refused.value) == line


@pytest.mark.parametrize(
    ("design", "options", "line"),
    [
        ("pi", {"estimator": "Kalman"}, "unknown estimator 'Kalman'; expected one of none, kalman"),
        (
            "pi",
            {"anti_windup": "Conditional"},
            "unknown anti-windup 'Conditional'; expected one of conditional, back-calculation, none",
        ),
        (
            "poles",
            {"poles": [0.5, 0.5]},
            "--poles must be text like '0.8,0.7+0.1j,0.7-0.1j', got [0.5, 0.5]",
        ),
    ],
)
def test_a_design_field_of_the_wrong_kind(
    workdir: Path, design: str, options: dict[str, object], line: str
) -> None:
    # estimator='Kalman' designed a PI without an estimator and saved a file whose command line
    # ('--estimator Kalman') the CLI refuses; a list of poles raised AttributeError
    with pytest.raises(CartctlError) as refused:
        getattr(cartctl, f"design_{design}")("models/ground.toml", **options)
    assert str(refused.value) == line


@pytest.mark.parametrize(
    ("option", "line"),
    [
        ("crossover_hz", "--crossover-hz must be in (0, 50) Hz"),
        ("step_rad_s", "--step must be a non-zero speed in rad/s"),
        ("voltage_limit_v", "--voltage-limit must be in (0, 12] V"),
    ],
)
def test_a_whole_number_beyond_any_float(workdir: Path, option: str, line: str) -> None:
    # 10**400 raised OverflowError (int too large to convert to float) from the range checks
    with pytest.raises(CartctlError) as refused:
        cartctl.design_pi("models/ground.toml", **{option: 10**400})
    assert str(refused.value).startswith(line) and ", got 1000" in str(refused.value)


def test_a_design_option_by_another_name(workdir: Path) -> None:
    # a TypeError naming DesignRequest.__init__ (an option by its command-line name, a typo)
    with pytest.raises(CartctlError) as refused:
        cartctl.design_pi("models/ground.toml", estimator="kalman", process_noise_v=0.2)
    assert str(refused.value) == (
        "design_pi has no option 'process_noise_v'; --process-noise-v is process_noise_std_v"
    )
    with pytest.raises(CartctlError) as refused:
        cartctl.design_poles("models/ground.toml", settling=0.1)
    assert str(refused.value).startswith(
        "design_poles has no option 'settling'; the options are anti_windup, bandwidth_hz, "
    )


def test_a_design_of_one_motor_records_its_command(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    # Design.command() (the saved file's regenerate line) left out --motor: it made both motors
    design = cartctl.design_pi("models/ground.toml", motors=("b",), crossover_hz=4)
    assert design.command().endswith(" --motor b")
    assert "; design['b'] has every figure" in repr(design)  # its hint named design['a']
    design.save("api.toml")
    argv = shlex.split(design.command())[1:]
    assert main([*argv, "--out", "cli.toml"]) == 0
    capsys.readouterr()
    api, cli = (load_controller(name) for name in ("api.toml", "cli.toml"))
    assert set(api.motors) == set(cli.motors) == {"b"}
    assert api.motors["b"]["kp"] == cli.motors["b"]["kp"]
    with pytest.raises(CartctlError, match=r"motors must be 'a' and/or 'b', got \[\]"):
        cartctl.design_pi("models/ground.toml", motors=())


@pytest.mark.parametrize("seed", [-1, 1.5, "3"])
def test_a_seed_that_is_no_seed(workdir: Path, seed: object) -> None:
    # simulate raised numpy's ValueError or TypeError; excite on physics took -1 and 1.5
    for call in (cartctl.excite, lambda **kw: cartctl.simulate("controllers/pi.toml", **kw)):
        with pytest.raises(CartctlError) as refused:
            call(seed=seed)
        assert str(refused.value) == f"a seed is a whole number >= 0, got {seed!r}"


def test_a_motor_a_result_does_not_have(workdir: Path) -> None:
    # a one-motor design or identification raised a bare KeyError: 'a'
    design = cartctl.design_pi("models/ground.toml", motors=("b",))
    with pytest.raises(CartctlError, match=r"^no motor 'a' in this design; it has motor\(s\) b$"):
        design["a"]
    ident = cartctl.identify(cartctl.excite(plant="physics", cycles=2, motor="b"), motors=("b",))
    with pytest.raises(CartctlError, match=r"^no motor 'a' in this identification; it has motor"):
        ident["a"]
    assert "ident['b'] for one motor" in repr(ident)  # its hint named ident['a']
    assert design["b"]["kp"] > 0 and ident["b"].model.nk == 2


@pytest.mark.parametrize(
    ("options", "line"),
    [
        ({"amplitude_v": float("nan")}, "amplitude_v must be a number, got nan"),
        ({"amplitude_v": "10"}, "amplitude_v must be a number, got '10'"),
        ({"amplitude_v": None}, "amplitude_v must be a number, got None"),
        ({"signal": "prbs", "duration_s": True}, f"{_DURATION}, got True"),
        ({"signal": "prbs", "duration_s": "2"}, f"{_DURATION}, got '2'"),
        ({"noise_std_rad_s": "0.1"}, "--noise must be a number, got '0.1'"),
        ({"cycles": 2.5}, "--cycles must be a whole number, got 2.5"),
        ({"cycles": float("nan")}, "--cycles must be a whole number, got nan"),
    ],
)
def test_excite_refuses_a_value_of_the_wrong_kind(
    workdir: Path, options: dict[str, object], line: str
) -> None:
    # a NaN amplitude was said to be beyond the supply; cycles=2.5 raised numpy's TypeError
    with pytest.raises(CartctlError) as refused:
        cartctl.excite(**options)  # type: ignore[arg-type]
    assert str(refused.value) == line


@pytest.mark.parametrize(
    ("options", "line"),
    [
        ({"duration_s": True}, f"{_DURATION}, got True"),
        ({"duration_s": None}, f"{_DURATION}, got None"),
        ({"duration_s": "2"}, f"{_DURATION}, got '2'"),
        ({"reference": 5}, "--reference: unknown reference 5; expected " + FORMS),
        ({"reference": None}, "--reference: unknown reference None; expected " + FORMS),
        ({"plant": None}, "simulate runs on 'sim' or 'physics[:actuation_ms=X]', not 'None'"),
        ({"noise_std_rad_s": None}, "--noise must be a number, got None"),
    ],
)
def test_simulate_refuses_a_value_of_the_wrong_kind(
    workdir: Path, options: dict[str, object], line: str
) -> None:
    # duration_s=True ran 1 s and '2' ran 2 s; None, a reference or plant that is no text and a
    # noise given as text raised TypeError or AttributeError ('int' object has no attribute
    # 'partition')
    assert _simulate_line("controllers/pi.toml", **options) == line


def test_identify_refuses_a_prefilter_that_is_no_number(workdir: Path) -> None:
    # prefilter_hz=True filtered at 1 Hz; '10' raised TypeError
    trace = cartctl.excite(plant="physics", cycles=1)
    for cutoff in (True, "10"):
        with pytest.raises(CartctlError) as refused:
            cartctl.identify(trace, prefilter_hz=cutoff)  # type: ignore[arg-type]
        assert str(refused.value) == (
            f"prefilter cut-off (--cutoff-hz) must be a number, got {cutoff!r}"
        )


def test_save_where_no_file_can_be(capsys: pytest.CaptureFixture[str], workdir: Path) -> None:
    # Design.save, Identification.save and save_model raised IsADirectoryError for a folder
    (workdir / "folder").mkdir()
    assert main(["design", "models/ground.toml", "--method", "pi", "--out", "folder"]) == 2
    assert "--out folder: is a folder, not a file" in capsys.readouterr().err
    design = cartctl.design_pi("models/ground.toml")
    ident = cartctl.identify(cartctl.excite(plant="physics", cycles=2))
    for save in (design.save, ident.save, lambda p: cartctl.save_model(ident, p)):
        with pytest.raises(CartctlError, match=r"^save folder: is a folder, not a file$"):
            save("folder")
    with pytest.raises(CartctlError, match="save_model takes load_model's or identify's result"):
        cartctl.save_model("models/ground.toml", "x.toml")  # type: ignore[arg-type]
    assert not list((workdir / "folder").iterdir())


@pytest.mark.parametrize("ticks", [1.5, True])
def test_identify_refuses_a_loop_delay_that_is_not_whole(workdir: Path, ticks: object) -> None:
    # 1.5 was shown in the summary and written as 1 into the model file (--loop-delay is an int)
    trace = cartctl.excite(plant="physics", cycles=2)
    with pytest.raises(CartctlError) as refused:
        cartctl.identify(trace, loop_delay_ticks=ticks)  # type: ignore[arg-type]
    assert str(refused.value) == f"--loop-delay must be in 0..50 ticks, got {ticks}"


def test_identify_takes_numpy_whole_numbers_and_refuses_a_bool(workdir: Path) -> None:
    # delay=np.int64(2) and prefilter_order=np.int64(4) were refused as not whole; delay=True ran
    # as nk = 1
    trace = cartctl.excite(plant="physics", cycles=2)
    given = cartctl.identify(trace, delay=np.int64(2), prefilter_hz=15, prefilter_order=np.int64(4))
    plain = cartctl.identify(trace, delay=2, prefilter_hz=15, prefilter_order=4)
    np.testing.assert_array_equal(given["a"].theta, plain["a"].theta)
    with pytest.raises(
        CartctlError, match=r"^delay must be a whole number of ticks or 'auto', got True$"
    ):
        cartctl.identify(trace, delay=True)


@pytest.mark.parametrize(
    ("options", "line"),
    [
        ({"na": True}, "na (--na) must be a whole number in 0..50, got True"),
        ({"nb": True}, "nb (--nb) must be a whole number in 1..50, got True"),
        (
            {"prefilter_hz": 15, "prefilter_order": True},
            "prefilter order (--order) must be a whole number in 1..12, got True",
        ),
    ],
)
def test_identify_refuses_a_bool_for_an_order(
    workdir: Path, options: dict[str, object], line: str
) -> None:
    # na=True, nb=True and prefilter_order=True ran as 1 (choices.is_whole refuses bools)
    trace = cartctl.excite(plant="physics", cycles=1)
    with pytest.raises(CartctlError) as refused:
        cartctl.identify(trace, **options)  # type: ignore[arg-type]
    assert str(refused.value) == line


def test_a_design_or_run_of_something_else(workdir: Path) -> None:
    # an Identification given to design_pi or simulate raised TypeError from pathlib
    ident = cartctl.identify(cartctl.excite(plant="physics", cycles=2))
    for design in (cartctl.design_pi, cartctl.design_poles):
        with pytest.raises(CartctlError, match=r"^design from a saved model file: give its path"):
            design(ident)  # type: ignore[arg-type]
    with pytest.raises(CartctlError) as refused:
        cartctl.simulate(ident)  # type: ignore[arg-type]
    assert str(refused.value) == (
        "simulate runs a Design, a controller file or its path, not Identification"
    )
    model = cartctl.load_model("models/ground.toml")  # a model file read from a path designs
    assert cartctl.design_pi(model).model_path == model.path


@pytest.mark.parametrize(
    ("call", "line"),
    [
        (lambda: cartctl.identify(None), "identify takes a trace, its path or a list of them, not None"),
        (lambda: cartctl.identify(5), "identify takes a trace, its path or a list of them, not 5"),
        (lambda: cartctl.design_pi("models/ground.toml", motors=None),
         "motors must be 'a' and/or 'b', got None"),
        (lambda: cartctl.load_trace("logs/x.csv", map=5),
         "map must be text like 'voltage_a=FloatIn2,speed_a=FloatIn0' or a dict, got 5"),
    ],
)  # fmt: skip
def test_a_container_of_the_wrong_kind(workdir: Path, call: Any, line: str) -> None:
    # TypeError ('NoneType' object is not iterable) or AttributeError ('int' object has no
    # attribute 'items')
    with pytest.raises(CartctlError) as refused:
        call()
    assert str(refused.value) == line


@pytest.mark.parametrize(
    ("argv", "options"),
    [
        (["--noise", "-1"], {"noise_std_rad_s": -1.0}),
        (["--noise", "nan"], {"noise_std_rad_s": float("nan")}),
        (["--reference", "bogus"], {"reference": "bogus"}),
        (["--reference", "square:8:0"], {"reference": "square:8:0"}),
    ],
)
def test_simulate_names_the_noise_and_reference_as_run_does(
    capsys: pytest.CaptureFixture[str], workdir: Path, argv: list[str], options: dict[str, object]
) -> None:
    # simulate said 'noise must be ...' (its NaN 'a standard deviation') and left out run's
    # '--reference: ' before the reference's line
    line = _run_line(capsys, "--controller", "controllers/pi.toml", *argv)
    assert line.startswith(argv[0])
    assert _simulate_line("controllers/pi.toml", **options) == line
    assert _excite_line(capsys, "--noise", "-1") == _excite_error(noise_std_rad_s=-1.0)


def _excite_error(**options: object) -> str:
    with pytest.raises(CartctlError) as refused:
        cartctl.excite(**options)  # type: ignore[arg-type]
    return str(refused.value)


def test_motors_given_as_the_command_lines_word() -> None:
    # the message spelled the string out letter by letter: ['b', 'o', 't', 'h']
    with pytest.raises(CartctlError, match=r"^motors must be 'a' and/or 'b', got 'both'$"):
        cartctl.design_pi("models/ground.toml", motors="both")


@pytest.mark.parametrize("delay", [-1, 51])
def test_identify_refuses_a_delay_out_of_range_in_one_line(
    workdir: Path, capsys: pytest.CaptureFixture[str], delay: int
) -> None:
    # the command line said "--delay must be in 0..50 ticks", the API "nk (--delay) must be ..."
    argv = ["excite", "--plant", "physics", "--amplitude", "10", "--cycles", "2", "--out", "sq.csv"]
    assert main(argv) == 0
    with pytest.raises(CartctlError) as refused:
        cartctl.identify("sq.csv", delay=delay)
    assert main(["identify", "sq.csv", f"--delay={delay}"]) == 2
    line = capsys.readouterr().err.strip().removeprefix("cartctl identify: error: ")
    assert (
        line == str(refused.value) == f"nk (--delay) must be a whole number in 0..50, got {delay}"
    )


def test_the_overrides_the_refusals_name_run_in_the_api_too(workdir: Path) -> None:
    # the refusals end "or pass --allow-unstable" / "--allow-delay-mismatch": simulate takes both
    text = (workdir / "models" / "ground.toml").read_text(encoding="utf-8")
    unstable = workdir / "models" / "unstable.toml"
    unstable.write_text(text.replace("[-0.9356, 0.2173,", "[-2.1, 1.05,"), encoding="utf-8")
    ran = cartctl.simulate("controllers/pi.toml", model=str(unstable), duration_s=30,
                           allow_unstable=True)  # fmt: skip
    assert ran.failure is not None and "ran away" in ran.failure
    assert len(ran.columns["time_s"]) < 3000  # stopped early, as run --allow-unstable does
    with pytest.warns(UserWarning, match="designed for a loop delay of 3"):
        mismatched = cartctl.simulate("controllers/serial-pi.toml", plant="physics",
                                      duration_s=1, allow_delay_mismatch=True)  # fmt: skip
    assert (
        mismatched.failure is None and len(mismatched.columns["time_s"]) == 100 + 1
    )  # 1 s of 10 ms ticks, the stop row
