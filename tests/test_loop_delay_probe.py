"""The loop-delay probe does not guess: it judges a spread of echoes, and a run watches the delay.

The decision rule is tested without any timing (counts in, verdict out); then ``cartctl run`` on
the virtual cart with ``late``, a fault that makes the host's commands reach the cart a tick late
in stretches, so that the echoes spread over two delays (real time, about 2 s each).
"""

from __future__ import annotations

import json
import re
import warnings
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cartctl.cli import main
from cartctl.design.controllerfile import load_controller
from cartctl.errors import DataWarning, InputError
from cartctl.link.bridge import CLEAR_SHARE, MIN_ECHOES, EchoDelays, delay_change
from cartctl.link.cart_faults import LATE_STRETCH_TICKS, CartFaults
from cartctl.session.prepare import check_loop_delay

ROOT = Path(__file__).resolve().parents[1]
PI = str(ROOT / "controllers" / "pi.toml")  # designed for the on-board loop delay, 1 tick

# -- the measurement and its verdict (no timing) ------------------------------------------------


@pytest.mark.parametrize(
    ("counts", "mode", "clear"),
    [
        ({1: 20}, 1, True),
        ({1: 17, 2: 3}, 1, True),  # 85 %: the least share that is clear
        ({1: 16, 2: 4}, 1, False),  # 80 %
        ({2: 19}, 2, False),  # all agree, but fewer than 20 echoes
        ({1: 10, 2: 10}, 1, False),  # a tie: the shorter delay is named, and it is not clear
        ({2: 45, 1: 3, 3: 2}, 2, True),
        ({}, None, False),
    ],
)
def test_a_measurement_is_clear_only_with_20_echoes_mostly_agreeing(
    counts: dict[int, int], mode: int | None, clear: bool
) -> None:
    measured = EchoDelays.of(counts)
    assert (measured.mode, measured.clear) == (mode, clear)


def test_the_spread_is_described_and_in_the_json() -> None:
    measured = EchoDelays.of(Counter({1: 19, 2: 1}))
    assert measured.describe() == "1 tick in 19 of 20 echoes (95 %), 2 ticks in 1"
    assert measured.to_dict() == {"ticks": 1, "echoes": 20, "mode_share_percent": 95.0,
                                  "min": 1, "max": 2, "clear": True,
                                  "counts": {"1": 19, "2": 1}}  # fmt: skip


@given(st.dictionaries(st.integers(0, 6), st.integers(0, 60), max_size=5))
def test_clear_means_enough_echoes_and_the_clear_share_at_one_delay(counts: dict) -> None:
    total = sum(counts.values())
    top = max(counts.values(), default=0)
    measured = EchoDelays.of(counts)
    assert measured.echoes == total
    assert measured.clear == (total >= MIN_ECHOES and top >= CLEAR_SHARE * total > 0)
    if total:
        assert counts[measured.mode] == top
        assert measured.mode == min(d for d, n in counts.items() if n == top)


@pytest.mark.parametrize(
    ("counts", "delay", "verdict"),
    [
        ({1: 20}, 1, "runs"),
        ({2: 20}, 2, "refused"),  # clearly another loop than the controller's
        ({2: 18, 1: 2}, 2, "refused"),
        ({2: 14, 1: 6}, 2, "warns"),  # mostly 2, but not clear: run it, say how sure
        ({1: 12, 2: 8}, 1, "warns"),  # mostly the controller's, not clear either
        ({2: 19}, 2, "warns"),  # too few echoes to be sure
    ],
)
def test_run_refuses_a_mismatch_only_when_the_measurement_is_clear(
    counts: dict[int, int], delay: int, verdict: str
) -> None:
    controller = load_controller(PI)
    measured = EchoDelays.of(counts)
    if verdict == "refused":
        with pytest.raises(InputError, match=f"has {delay}") as refused:
            check_loop_delay(controller, PI, "serial:X", delay, allow=False, measured=measured)
        assert measured.describe() in str(refused.value)
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_loop_delay(controller, PI, "serial:X", delay, allow=False, measured=measured)
    if verdict == "warns":
        assert len(caught) == 1 and issubclass(caught[0].category, DataWarning)
        text = str(caught[0].message)
        assert "not clear" in text and measured.describe() in text
    else:
        assert caught == []


def test_a_plant_that_knows_its_delay_is_checked_as_before() -> None:
    with pytest.raises(InputError, match="has 2"):
        check_loop_delay(load_controller(PI), PI, "sim", 2, allow=False)


@pytest.mark.parametrize(
    ("run", "change"),
    [
        ({1: 498, 2: 3}, None),  # 0.6 % at 2: the loop the controller was checked against
        ({1: 450, 2: 50}, "varied (10 % of the commands took another than 1 tick)"),
        ({2: 400, 1: 100}, "changed"),
        ({}, None),
    ],
)
def test_a_run_that_leaves_the_probed_delay_is_a_change(
    run: dict[int, int], change: str | None
) -> None:
    text = delay_change(EchoDelays.of({1: 20}), EchoDelays.of(run))
    if change is None:
        assert text is None
    else:
        assert text is not None and text.startswith(f"the loop delay {change} during the run")


# -- the virtual cart's late stretches ------------------------------------------------------------


@pytest.mark.parametrize("late", [0.05, 0.1, 0.3, 0.5, 1.0])
def test_late_makes_that_share_of_ticks_late_in_stretches(late: float) -> None:
    faults = CartFaults.parse(f"late={late}")
    pattern = [faults.late_at(j) for j in range(2000)]
    assert abs(sum(pattern) / len(pattern) - late) < 0.02
    if late < 1.0:  # stretches of LATE_STRETCH_TICKS late ticks
        starts = [j for j in range(1, 2000) if pattern[j] and not pattern[j - 1]]
        assert starts and all(pattern[s : s + LATE_STRETCH_TICKS] == [True] * 5 for s in starts)
        assert all(not pattern[s + LATE_STRETCH_TICKS] for s in starts if s + 5 < 2000)
    assert not any(CartFaults().late_at(j) for j in range(100))


@pytest.mark.parametrize("text", ["late=2", "late=-0.1", "late=x"])
def test_a_bad_late_fraction_is_refused(text: str) -> None:
    with pytest.raises(InputError, match="late"):
        CartFaults.parse(text)


# -- cartctl run on the virtual cart (real time) ------------------------------------------------


def _run(capsys: pytest.CaptureFixture[str], plant: str) -> tuple[int, str, str]:
    """``cartctl run`` in this process (the ``workdir`` fixture's folder): exit code, out, err."""
    code = main(["run", "--plant", plant, "--duration", "1", "--rerun", "off", "--json"])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.realtime
def test_a_cart_whose_commands_all_come_a_tick_late_is_refused_clearly(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    code, _, err = _run(capsys, "virtual:late=1")
    assert code == 2, err
    errors = [line for line in err.splitlines() if line.startswith("cartctl run: error")]
    assert len(errors) == 1 and "has 2" in errors[0], err
    # the spread comes with it (a loaded machine may add an echo or two at 3 ticks)
    assert re.search(r"\(measured: 2 ticks in \d+ of \d+ echoes \(\d+ %\)", errors[0]), errors[0]
    assert not (workdir / "logs").exists() or not list((workdir / "logs").glob("*.csv"))


@pytest.mark.realtime
@pytest.mark.filterwarnings("always::cartctl.errors.DataWarning")  # the CLI prints it
def test_a_spread_delay_warns_runs_and_shows_in_the_summary(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    # late=0.5: stretches of 5 late ticks every 10 ticks; about 4 in 9 echoes at 2 ticks
    code, out, err = _run(capsys, "virtual:late=0.5")
    assert code == 0, err
    assert "Traceback" not in err
    warned = [line for line in err.splitlines() if "warning" in line]
    assert all(line.startswith("cartctl run: warning:") for line in warned), err
    assert any("loop delay" in line and "not clear" in line for line in warned), err
    assert any("during the run" in line for line in warned), err
    link = json.loads(out)["link"]
    probe = link["loop_delay_probe"]
    assert probe["clear"] is False and probe["echoes"] >= 50  # went on past the first 20
    seen = {int(d): n for d, n in link["loop_delay_ticks_seen"].items()}
    assert seen.get(1, 0) > 10 and seen.get(2, 0) > 10  # a loaded machine may add a few at 3
    assert link["loop_delay_change"] is not None


@pytest.mark.realtime
@pytest.mark.filterwarnings("always::cartctl.errors.DataWarning")
def test_a_clean_virtual_cart_measures_one_tick(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    code, out, err = _run(capsys, "virtual")
    assert code == 0, err
    summary = json.loads(out)
    link = summary["link"]
    # a busy machine holds the host up: the probe's echoes spread (seen: 1 tick in 32 of 50), it
    # warns 'not clear' and runs; the delay it names is still the most frequent one, 1 tick
    assert summary["loop_delay_ticks"] == link["loop_delay_probe"]["ticks"] == 1
    assert link["loop_delay_probe"]["echoes"] >= MIN_ECHOES
    seen = {int(d): n for d, n in link["loop_delay_ticks_seen"].items()}
    assert max(seen, key=lambda d: seen[d]) == 1


def test_the_link_line_names_the_report_s_nk_not_the_model_s() -> None:
    """A run of a controller designed on an nk = 1 model (what identify --delay auto and commission
    fit over serial) was told 'model nk = 2': that is the report's structure for the loop delay."""
    from cartctl.sinks.summary import format_summary

    metrics = ("overshoot_percent", "rise_time_s", "settling_time_s", "steady_state_error",
               "rms_error", "max_abs_voltage")  # fmt: skip
    link = {"port": "/dev/ttyACM0", "echo_delay_ticks": 1, "frames": 10, "crc_errors": 0,
            "garbage_bytes": 0, "lost_frames": 0, "missed_ticks": 0, "skipped_ticks": 0,
            "watchdog_trips": 0, "host_frames_sent": 10, "host_frames_lost": 0,
            "host_frames_lost_percent": 0.0}  # fmt: skip
    summary = {"ticks": 11, "duration_s": 0.1, "deadline_misses": 0, "metrics_signal": "speed",
               "period_error_us": {"p50": 1.0, "p99": 2.0, "max": 3.0},
               "compute_us": {"p50": 1.0, "p99": 2.0, "max": 3.0},
               "settling_band": {"fraction": 0.02, "floor_rad_s": 0.35},
               "motors": {"a": dict.fromkeys(metrics)}, "link": link,
               "loop_delay_ticks": 1, "controller_loop_delay_ticks": 1}  # fmt: skip
    text = format_summary(summary)
    assert "loop delay 1 ticks (echo 1; the report's model: nk = 2)" in text, text
    assert "model nk" not in text


def test_the_summary_shows_the_run_s_delays_the_probe_s_and_a_change() -> None:
    from cartctl.sinks.summary import delay_seen_lines

    probe, seen = EchoDelays.of({1: 20}), EchoDelays.of({1: 450, 2: 50})
    link = {"loop_delay_ticks_seen": seen.to_dict()["counts"], "loop_delay_probe": probe.to_dict(),
            "loop_delay_change": delay_change(probe, seen)}  # fmt: skip
    lines = delay_seen_lines(link)
    assert lines[0] == (
        "  loop delay seen over the run: 1 tick in 450 of 500 echoes (90 %), 2 ticks in 50; "
        "the probe before it: 1 tick in 20 of 20 echoes (100 %)"
    )
    assert len(lines) == 2 and lines[1].startswith("  the loop delay varied (10 %")
    assert delay_seen_lines({"port": "/dev/ttyACM0"}) == []  # a monitor's link: no run echoes
