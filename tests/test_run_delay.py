"""``cartctl run`` knows the loop delay of every plant and refuses a controller designed for
another one before driving; ``--voltage-limit`` is the limit the controllers work with."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.read import read_trace
from cartctl.design import controllerfile
from cartctl.errors import DataWarning
from cartctl.plants import factory

ROOT = Path(__file__).resolve().parents[1]
MISMATCH = (
    "cartctl run: error: controllers/{given} is designed for a loop delay of {designed} tick(s) "
    "but the plant '{plant}' has {delay}; use controllers/{fit} (designed for {delay}) or pass "
    "--allow-delay-mismatch"
)


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(["run", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def _errors(err: str) -> list[str]:
    """stderr lines of cartctl (the virtual cart's own 'cart: …' lines left out)."""
    return [line for line in err.splitlines() if not line.startswith("cart: ")]


def _nothing_written(workdir: Path) -> bool:
    return not (workdir / "logs").exists() or not any((workdir / "logs").iterdir())


@pytest.mark.parametrize(
    ("plant", "given", "fit"),
    [("sim", "serial-pi.toml", "pi.toml"), ("physics", "serial-poles.toml", "poles.toml")],
)
def test_serial_controller_on_a_simulator_stops_before_driving(
    capsys: pytest.CaptureFixture[str], workdir: Path, plant: str, given: str, fit: str
) -> None:
    code, out, err = _run(capsys, "--fast", "--plant", plant, "--controller",
                          f"controllers/{given}", "--rerun", "off")  # fmt: skip
    assert code == 2
    assert out == ""
    expected = MISMATCH.format(given=given, designed=3, plant=plant, delay=1, fit=fit)
    assert err.strip().splitlines() == [expected]
    assert _nothing_written(workdir)


def test_from_a_folder_without_controllers_the_refusal_names_the_shipped_file_that_fits(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Outside a checkout the shipped names resolve to the package's copies, and so does the
    file the refusal offers (it named none and advised a redesign)."""
    monkeypatch.chdir(tmp_path)
    code, out, err = _run(
        capsys, "--fast", "--controller", "controllers/serial-pi.toml", "--rerun", "off"
    )
    assert code == 2
    assert out == ""
    expected = MISMATCH.format(
        given="serial-pi.toml", designed=3, plant="sim", delay=1, fit="pi.toml"
    )
    assert err.strip().splitlines() == [expected]
    assert _nothing_written(tmp_path)


@pytest.mark.filterwarnings("always::cartctl.errors.DataWarning")  # the CLI prints it
def test_allow_delay_mismatch_runs_with_one_warning(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    code, out, err = _run(capsys, "--fast", "--controller", "controllers/serial-pi.toml",
                          "--allow-delay-mismatch", "--duration", "1", "--rerun", "off", "--json")  # fmt: skip
    assert code == 0, err
    lines = err.strip().splitlines()
    assert len(lines) == 1
    assert "warning" in lines[0] and "loop delay of 3 tick(s)" in lines[0] and "has 1" in lines[0]
    summary = json.loads(out)
    assert summary["loop_delay_ticks"] == 1
    assert summary["controller_loop_delay_ticks"] == 3


def test_sim_delay_comes_from_its_model(
    capsys: pytest.CaptureFixture[str], workdir: Path, ground_path: Path
) -> None:
    slow = workdir / "models" / "slow.toml"
    text = ground_path.read_text(encoding="utf-8")
    slower, count = re.subn(r"^nk = 2$", "nk = 3", text, flags=re.M)  # both motors one later
    assert count == 2
    slower, count = re.subn(r"^loop_delay_ticks = 1\b", "loop_delay_ticks = 2", slower, flags=re.M)
    assert count == 1  # recorded in a loop one tick longer, as the model's delay says
    slow.write_text(slower, encoding="utf-8")
    code, _out, err = _run(capsys, "--fast", "--model", "models/slow.toml", "--rerun", "off")
    assert code == 2
    # loop delay nk − 1 = 2: no shipped file is for it; pi.toml (1, extra 0) needs one more tick
    assert err.strip().splitlines() == [
        "cartctl run: error: controllers/pi.toml is designed for a loop delay of 1 tick(s) but the "
        "plant 'sim' has 2; redesign it with --extra-delay 1 or pass --allow-delay-mismatch"
    ]


@pytest.mark.parametrize("plant", ["sim", "physics"])
def test_summary_has_the_loop_delay_of_simulators(
    capsys: pytest.CaptureFixture[str], workdir: Path, plant: str
) -> None:
    code, out, err = _run(capsys, "--fast", "--plant", plant, "--duration", "0.5", "--rerun", "off")
    assert code == 0, err
    assert "loop delay 1 tick(s); the controller is designed for 1" in out
    assert "controller controllers/pi.toml" in out


@pytest.mark.realtime
# a heavily loaded machine can leave the probe unclear: the run warns and goes on (that warning:
# test_loop_delay_probe.py); what is checked here holds either way
@pytest.mark.filterwarnings("ignore::cartctl.errors.DataWarning")
def test_virtual_plant_takes_the_pi_controller(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    code, out, err = _run(capsys, "--plant", "virtual", "--reference", "step:8", "--duration",
                          "0.5", "--rerun", "off", "--json")  # fmt: skip
    assert code == 0, err
    summary = json.loads(out)
    assert summary["controller"] == "controllers/pi.toml"
    # bridge 2: the reply reaches the cart within the tick and io() applies it at the next one,
    # which echoes it: the on-board loop's delay
    assert summary["loop_delay_ticks"] == 1
    assert summary["controller_loop_delay_ticks"] == 1


@pytest.mark.realtime
def test_serial_controller_on_the_virtual_cart_stops_before_driving(
    capsys: pytest.CaptureFixture[str], workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sent: list[tuple[float, float, bool]] = []
    original = factory.make_plant

    def recording_make_plant(*args, **kwargs):
        plant, description = original(*args, **kwargs)
        send = plant.send

        def record(voltage_a_v: float, voltage_b_v: float, *, drive: bool = True) -> None:
            sent.append((voltage_a_v, voltage_b_v, drive))
            send(voltage_a_v, voltage_b_v, drive=drive)

        plant.send = record
        return plant, description

    monkeypatch.setattr(factory, "make_plant", recording_make_plant)
    unclear: DataWarning | None = None
    try:
        code, _out, err = _run(capsys, "--plant", "virtual", "--controller",
                              "controllers/serial-pi.toml", "--rerun", "off")  # fmt: skip
    except DataWarning as warning:
        unclear = warning
    if unclear is not None:
        # A loaded machine can answer some of the probe's ticks late (1 run in 10 with both
        # cores busy: 1 tick in 37 of 50 echoes, 2 in 13): the delay is then not clear, and the
        # run only warns (test_loop_delay_probe.py), an error here, raised before driving too.
        # The refusal below needs a clear probe, which no test on a busy machine can promise.
        assert "is not clear" in str(unclear)
    else:
        assert code == 2
        # serial-pi.toml is the fallback for a serial loop of 3 ticks; the bridge's loop has 1
        expected = MISMATCH.format(given="serial-pi.toml", designed=3, plant="virtual", delay=1,
                                   fit="pi.toml")  # fmt: skip
        # a measured delay says how sure it is: the probe's echoes (clear, or it would only warn)
        head, _, tail = expected.partition("; ")
        (line,) = _errors(err)
        assert line.startswith(head + " (measured: 1 tick in ") and line.endswith("; " + tail)
    assert sent, "the echo was measured by sending"
    assert all(not drive and a == 0.0 and b == 0.0 for a, b, drive in sent)
    assert _nothing_written(workdir)


# -- the voltage limit ------------------------------------------------------------------------


@pytest.mark.filterwarnings("always::cartctl.errors.DataWarning")  # 10 rad/s is beyond 4 V's reach
def test_voltage_limit_is_the_controllers_limit(
    capsys: pytest.CaptureFixture[str], workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """10 rad/s needs 4.95 V on the ground model (DC gain 2.02 rad/s/V): at 4 V the PI saturates
    for 1 s, then the reference drops to 6 rad/s (2.97 V). Designed for 4 V, its integral stops
    where the command is on the limit, so the command leaves the limit on the very tick of the
    drop; a PI limited at 12 V and clamped after would have wound up towards 12 V and hold 4 V
    for tens of ticks."""
    (workdir / "ref.csv").write_text("time_s,reference\n0,10\n0.999,10\n1.0,6\n3,6\n", "utf-8")
    built = []
    original = controllerfile.build_controllers

    def capture(*args, **kwargs):
        controllers = original(*args, **kwargs)
        built.append(controllers)
        return controllers

    monkeypatch.setattr(controllerfile, "build_controllers", capture)
    code, out, err = _run(capsys, "--fast", "--voltage-limit", "4", "--reference", "file:ref.csv",
                          "--duration", "2", "--rerun", "off", "--json")  # fmt: skip
    assert code == 0, err
    assert [c.voltage_limit_v for c in built[0].values()] == [4.0, 4.0]
    trace = read_trace(json.loads(out)["trace"])
    for motor in ("a", "b"):
        u = trace.column(f"voltage_{motor}")
        assert np.max(np.abs(u)) <= 4.0
        drop = int(np.flatnonzero(trace.column(f"reference_{motor}") == 6.0)[0])
        assert u[drop - 1] == pytest.approx(4.0)  # saturated while 10 rad/s was asked
        assert u[drop] < 4.0 - 0.1  # no wound-up integral to unwind
        speed = trace.column(f"speed_{motor}")
        assert np.all(speed[drop + 30 :] < 6.0 + 0.3)  # and no windup overshoot after it


def test_voltage_limit_above_the_files_is_refused(
    capsys: pytest.CaptureFixture[str], workdir: Path
) -> None:
    text = (workdir / "controllers" / "pi.toml").read_text(encoding="utf-8")
    low = text.replace("voltage_limit_v = 12.0", "voltage_limit_v = 6.0")
    (workdir / "controllers" / "low.toml").write_text(low, encoding="utf-8")
    code, _, err = _run(capsys, "--fast", "--controller", "controllers/low.toml",
                        "--voltage-limit", "8", "--rerun", "off")  # fmt: skip
    assert code == 2
    assert err.strip().splitlines() == [
        "cartctl run: error: --voltage-limit 8 V is above the 6 V controllers/low.toml is "
        "designed for; it can only be lowered"
    ]
