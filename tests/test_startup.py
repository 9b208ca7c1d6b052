"""Start-up: building the parser loads no numerical or plotting library, and the parser is the same.

The commands import numpy, scipy, filterpy, matplotlib, Rerun and the serial stack when they run,
not when ``cartctl`` parses its arguments (``cartctl --help`` stays fast; the timing is in
``benchmarks/bench_startup.py``). The names, limits and defaults the parser shows live in light
modules (``cartctl.choices``, ``cartctl.design.request``) that the implementations import too.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from cartctl.cli import build_parser, main

HEAVY = ("numpy", "scipy", "control", "matplotlib", "rerun", "filterpy", "pymavlink", "serial",
         "pyarrow")  # fmt: skip
COMMANDS = ("excite", "identify", "inspect", "validate", "linearity", "design", "run", "review",
            "tune", "convert", "export", "virtual-cart", "monitor", "commission")  # fmt: skip

# The option strings of every command, as the parser had them before the imports became lazy.
OPTIONS = {
    "commission": ["--connect-timeout", "--help", "--jobs", "--json", "--noise", "--out", "--preset", "--seed", "-h"],
    "convert": ["--help", "--json", "--map", "--out", "-h"],
    "design": ["--anti-windup", "--bandwidth-hz", "--bias-drift-v", "--crossover-hz", "--disturbance-v", "--estimator", "--extra-delay", "--help", "--json", "--loop-delay", "--measurement-noise", "--method", "--motor", "--out", "--overshoot", "--phase-margin", "--poles", "--process-noise-v", "--report", "--settling-time", "--step", "--timing-noise-ticks", "--voltage-limit", "-h"],
    "excite": ["--amplitude", "--connect-timeout", "--cycles", "--duration", "--help", "--json", "--model", "--motor", "--noise", "--out", "--plant", "--preset", "--seed", "--signal", "-h"],
    "export": ["--arduino", "--help", "--mat", "--out", "-h"],
    "identify": ["--average", "--compare", "--cutoff-hz", "--delay", "--help", "--json", "--loop-delay", "--map", "--method", "--motor", "--na", "--nb", "--order", "--orders", "--out", "--prefilter", "--report", "--split", "--validate-on", "--zero-phase", "-h"],
    "inspect": ["--help", "--json", "-h"],
    "linearity": ["--help", "--json", "--map", "--motor", "--plot", "-h"],
    "monitor": ["--connect-timeout", "--connect-url", "--duration", "--help", "--json", "--labels", "--name", "--onboard", "--out", "--reference", "--rerun", "-h"],
    "review": ["--compare", "--help", "--json", "--map", "--model", "--screenshot", "--web", "-h"],
    "run": ["--allow-delay-mismatch", "--allow-unstable", "--connect-timeout", "--connect-url", "--controller", "--duration", "--fast", "--force", "--help", "--json", "--model", "--name", "--noise", "--out", "--plant", "--preset", "--reference", "--reference-b", "--rerun", "--seed", "--voltage-limit", "-h"],
    "tune": ["--actuation-ms", "--bias-drift-v", "--choose", "--duration", "--extra-delay", "--grid", "--help", "--jobs", "--json", "--max-overshoot", "--max-settling", "--method", "--out", "--plant", "--plants", "--plot", "--preset", "--process-noise-v", "--reference", "--robust", "--seed", "-h"],
    "validate": ["--help", "--json", "--map", "--motor", "--plot", "-h"],
    "virtual-cart": ["--duration", "--faults", "--help", "--noise", "--onboard", "--preset", "--reference", "--seed", "-h"],
}  # fmt: skip


def _child(code: str) -> str:
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return proc.stdout.strip()


def test_building_the_parser_loads_no_heavy_library() -> None:
    code = (
        "import sys; from cartctl.cli import build_parser; build_parser(); "
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))"
    )
    assert _child(code) == "[]"


def test_help_loads_no_heavy_library() -> None:
    code = (
        "import sys, contextlib, io\n"
        "from cartctl.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    for argv in [['--help']] + [[c, '--help'] for c in sys.argv[1:]]:\n"
        "        try:\n"
        "            main(argv)\n"
        "        except SystemExit as exc:\n"
        "            assert exc.code == 0, (argv, exc.code)\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))"
    )
    proc = subprocess.run([sys.executable, "-c", code, *COMMANDS], capture_output=True,
                          text=True, check=True)  # fmt: skip
    assert proc.stdout.strip() == "[]"


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_exits_0_with_the_usage(
    command: str | None, capsys: pytest.CaptureFixture[str]
) -> None:
    """Through :func:`cartctl.cli.main` in this process, as ``python -m cartctl`` calls it (its
    exit status: ``SystemExit(main())``); what a new process imports: the two tests above."""
    argv = ["--help"] if command is None else [command, "--help"]
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's exit after the help
        status = exc.code
    out, err = capsys.readouterr()
    assert status in (0, None), err  # the process's exit code 0
    assert out.startswith("usage: cartctl" + ("" if command is None else f" {command}"))
    assert err == ""


def _subparsers() -> dict:
    parser = build_parser()
    (action,) = [a for a in parser._actions if a.dest == "command"]
    return dict(action.choices)


def test_every_command_is_there_with_its_options() -> None:
    subs = _subparsers()
    assert tuple(subs) == COMMANDS
    for command, options in OPTIONS.items():
        have = [o for a in subs[command]._actions for o in a.option_strings]
        assert sorted(have) == sorted(options), command


def test_the_parser_and_the_implementations_share_one_definition() -> None:
    """Each name, limit and default the parser shows is defined once (no copy to drift)."""
    from cartctl import choices, reference, signals
    from cartctl.cli.commands import design, options, tune
    from cartctl.design import kalman, request
    from cartctl.link import cart_link
    from cartctl.plants import factory
    from cartctl.runtime import pi
    from cartctl.tune.grid import AXES

    assert options.DEFAULT_MODEL is factory.DEFAULT_MODEL is choices.DEFAULT_MODEL
    assert options.MAX_DURATION_S is signals.MAX_DURATION_S is choices.MAX_DURATION_S
    assert options.FORMS is reference.FORMS is choices.FORMS
    assert options.SIGNALS is signals.SIGNALS is choices.SIGNALS
    assert options.DEFAULT_CONNECT_TIMEOUT_S is cart_link.DEFAULT_CONNECT_TIMEOUT_S
    assert design.ANTI_WINDUP is pi.ANTI_WINDUP
    assert kalman.DEFAULT_PROCESS_NOISE_STD_V is request.DEFAULT_PROCESS_NOISE_STD_V
    assert kalman.DEFAULT_BIAS_DRIFT_STD_V is request.DEFAULT_BIAS_DRIFT_STD_V
    assert tuple(AXES) == tune.METHODS  # one grid per method tune offers


def test_parsed_defaults_are_the_home_values() -> None:
    from cartctl.link.cart_faults import CartFaults

    parser = build_parser()
    assert parser.parse_args(["virtual-cart"]).faults == CartFaults()


def test_no_help_text_shows_a_doubled_percent_sign() -> None:
    """argparse %-formats option help but not descriptions: a '%%' there is printed as is."""
    for name, parser in _subparsers().items():
        assert "%%" not in parser.format_help(), name
