"""The smoothed speed through the CLI: a physics run (which knows the true speed) reviewed as a
real cart's trace would be (its true-speed columns dropped), the model from --model or from the
run's recording, the note without a model, and the recording's smoothed series.

Expectations come from the simulator's true speed, not from the smoother's own output.
"""

from __future__ import annotations

import csv
import json
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.data.read import read_trace
from cartctl.design.kalman import smooth_speed

ROOT = Path(__file__).resolve().parents[1]
GROUND = str(ROOT / "models" / "ground.toml")


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _without_true_speed(src: Path, dst: Path) -> Path:
    """A copy of a run trace as a real cart's: the ``true_speed_*`` columns dropped."""
    with src.open(newline="") as f:
        rows = list(csv.reader(f))
    keep = [i for i, name in enumerate(rows[0]) if not name.startswith("true_speed")]
    with dst.open("w", newline="") as f:
        csv.writer(f).writerows([[row[i] for i in keep] for row in rows])
    return dst


@pytest.fixture(scope="module")
def physics_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s physics run (square reference: reversals, where the encoder lags most) with its
    recording, on the simulated clock."""
    out = tmp_path_factory.mktemp("smoothed")
    code = main(["run", "--plant", "physics", "--fast", "--duration", "3", "--reference",
                 "square:8:0.5", "--out", str(out), "--name", "p", "--rerun", "save",
                 "--json"])  # fmt: skip
    assert code == 0
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def test_smoothed_speed_of_a_physics_run_halves_the_encoders_rms_error(physics_run: Path) -> None:
    cols = read_trace(physics_run / "p.csv").columns()
    models = load_models(GROUND)
    for m in "ab":
        true, encoder = cols[f"true_speed_{m}"], cols[f"speed_{m}"]
        smoothed = smooth_speed(models.motor(m), cols[f"voltage_{m}"], encoder).speed_rad_s
        assert _rms(smoothed - true) <= 0.5 * _rms(encoder - true), m


def test_review_without_true_speed_gives_both_metrics_and_smoothed_is_truer(
    capsys: pytest.CaptureFixture[str], physics_run: Path, tmp_path: Path
) -> None:
    code, out, err = _cli(capsys, "review", str(physics_run / "p.csv"), "--json")
    assert code == 0, err
    true = json.loads(out)  # the simulator's true speed: the reference for both
    assert true["metrics_signal"] == "true_speed" and "smoothed" not in true["motors"]["a"]
    cart = _without_true_speed(physics_run / "p.csv", tmp_path / "cart.csv")
    code, out, err = _cli(capsys, "review", str(cart), "--json", "--model", GROUND)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["metrics_signal"] == "speed"
    assert doc["smoothed"]["model"] == GROUND and doc["smoothed"]["method"] == "kalman-rts"
    for m in "ab":
        encoder, smoothed = doc["motors"][m], doc["motors"][m]["smoothed"]
        assert set(smoothed) == set(encoder) - {"smoothed"}  # the same JSON output keys
        for key in ("overshoot_percent", "rms_error"):
            truth = true["motors"][m][key]
            assert abs(smoothed[key] - truth) < abs(encoder[key] - truth), (m, key)
    code, out, _ = _cli(capsys, "review", str(cart), "--model", GROUND)
    lines = out.splitlines()
    assert any(line.split()[:2] == ["a", "encoder"] for line in lines)
    assert any(line.split()[:2] == ["a", "smoothed"] for line in lines)
    assert any("Kalman RTS" in line and GROUND in line for line in lines)


def test_review_takes_the_model_from_the_runs_recording(
    capsys: pytest.CaptureFixture[str], physics_run: Path, tmp_path: Path
) -> None:
    cart = _without_true_speed(physics_run / "p.csv", tmp_path / "p.csv")
    (tmp_path / "p.rrd").write_bytes((physics_run / "p.rrd").read_bytes())
    code, out, err = _cli(capsys, "review", str(cart), "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert Path(doc["smoothed"]["model"]).resolve() == Path(GROUND).resolve()
    assert "smoothed" in doc["motors"]["a"]


def test_without_a_model_one_line_says_so_and_the_encoder_metrics_stand(
    capsys: pytest.CaptureFixture[str], physics_run: Path, tmp_path: Path
) -> None:
    cart = _without_true_speed(physics_run / "p.csv", tmp_path / "alone.csv")
    code, out, err = _cli(capsys, "review", str(cart))
    assert code == 0 and err == ""
    notes = [line for line in out.splitlines() if "need a model" in line]
    assert len(notes) == 1 and "--model" in notes[0]
    code, out, _ = _cli(capsys, "review", str(cart), "--json")
    doc = json.loads(out)
    assert doc["smoothed"]["model"] is None and "smoothed" not in doc["motors"]["a"]
    assert doc["motors"]["a"]["overshoot_percent"] is not None


def test_a_missing_model_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], physics_run: Path, tmp_path: Path
) -> None:
    cart = _without_true_speed(physics_run / "p.csv", tmp_path / "c.csv")
    code, out, err = _cli(capsys, "review", str(cart), "--model", str(tmp_path / "none.toml"))
    assert code == 2 and out == ""
    assert "none.toml" in err and len(err.strip().splitlines()) == 1


def test_a_model_of_one_motor_smooths_that_motor_and_says_so_for_the_other(
    capsys: pytest.CaptureFixture[str], physics_run: Path, tmp_path: Path
) -> None:
    """``--model`` with only motor a's model was refused ('no model for motor 'b''): motor a is
    smoothed, one line says motor b has none (the trace, the recording)."""
    text = Path(GROUND).read_text()
    one = tmp_path / "one.toml"
    one.write_text(text[: text.index("[motors.b]")])
    cart = _without_true_speed(physics_run / "p.csv", tmp_path / "cart.csv")
    code, out, err = _cli(capsys, "review", str(cart), "--json", "--model", str(one))
    assert code == 0, err
    doc = json.loads(out)
    assert "smoothed" in doc["motors"]["a"] and "smoothed" not in doc["motors"]["b"]
    assert "motor b" in doc["smoothed"]["note"]
    code, out, err = _cli(capsys, "review", str(cart), "--model", str(one))
    assert code == 0 and err == "", err
    lines = out.splitlines()
    assert any(line.split()[:2] == ["a", "smoothed"] for line in lines)
    assert not any(line.split()[:2] == ["b", "smoothed"] for line in lines)
    assert len([line for line in lines if "motor b" in line]) == 1
    code, out, err = _cli(capsys, "review", str(physics_run / "p.rrd"), "--model", str(one),
                          "--screenshot", str(tmp_path / "shot.png"))  # fmt: skip
    assert code == 0, err
    assert (tmp_path / "shot.png").is_file()


def test_review_of_a_recording_adds_the_smoothed_series(physics_run: Path) -> None:
    from cartctl.cli.commands.review.smoothed import recording_summary

    text, extra = recording_summary(physics_run / "p.rrd", GROUND)
    n = len(read_trace(physics_run / "p.csv"))
    assert extra is not None and set(extra) == {"motor/a/smoothed_speed", "motor/b/smoothed_speed"}
    assert all(len(values) == n for _, _, values in extra.values())
    assert "a smoothed" in text and "a true" in text


def test_the_runs_recording_holds_the_smoothed_speed(
    tmp_path: Path, physics_run: Path, rrd_rows: Callable[[str | Path], Counter]
) -> None:
    from cartctl.cli.commands.review.smoothed import smooth_run
    from cartctl.sinks.rerun_sink import HeldRerunSink
    from cartctl.sinks.summary import trace_metrics

    cart = _without_true_speed(physics_run / "p.csv", tmp_path / "cart.csv")
    trace = read_trace(cart)
    cols = trace.columns()
    sink = HeldRerunSink("save", tmp_path / "cart.rrd", strict=True)
    sink.open(list(cols))
    for row in zip(*cols.values(), strict=True):
        sink.write(row)
    sink.close()  # the loop's close: the rows go, the recording stays open
    summary = trace_metrics(cols, trace.period_s)
    smooth_run(summary, cols, trace.period_s, GROUND, sink)
    rows = rrd_rows(tmp_path / "cart.rrd")
    assert rows["motor/a/smoothed_speed"] == rows["motor/a/speed"] == len(trace)
    assert rows["motor/b/smoothed_speed"] == len(trace)
    assert "smoothed" in summary["motors"]["a"]


def test_a_held_recording_is_readable_when_the_process_ends_before_its_release(
    tmp_path: Path, rrd_rows: Callable[[str | Path], Counter]
) -> None:
    import subprocess
    import sys

    path = tmp_path / "held.rrd"
    script = (
        "from cartctl.sinks.rerun_sink import HeldRerunSink\n"
        f"s = HeldRerunSink('save', {str(path)!r}); s.open(['time_s', 'tick', 'speed_a'])\n"
        "for k in range(30): s.write((k * 0.01, k, 1.0))\n"
        "s.close()\n"
        "raise SystemExit(3)  # a failure after the loop, before the smoothed speed\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=60)
    assert done.returncode == 3, done.stderr
    assert rrd_rows(path)["motor/a/speed"] == 30


def test_a_serial_path_trace_gets_both_with_the_model_of_the_controller_it_ran(
    capsys: pytest.CaptureFixture[str], physics_run: Path, tmp_path: Path
) -> None:
    trace = tmp_path / "v.csv"
    trace.write_bytes((physics_run / "p.csv").read_bytes())  # true speed kept, as virtual's
    controller = ROOT / "controllers" / "pi.toml"
    (tmp_path / "v.meta.toml").write_text(
        'format = "cartctl-trace-meta/1"\n'
        'plant = "virtual cart on /dev/pts/9 (physics preset ground)"\n'
        "loop_delay_ticks = 1\n"
        f'command = "cartctl run --plant virtual --controller {controller}"\n'
        f'controller = "{controller}"\n'  # as run writes it; the model from the controller
    )
    code, out, err = _cli(capsys, "review", str(trace), "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["metrics_signal"] == "true_speed"  # motors.a stays the true speed's
    assert Path(doc["smoothed"]["model"]).resolve() == Path(GROUND).resolve()
    assert doc["smoothed"]["extra_delay_ticks"] == 0
    true, smoothed = doc["motors"]["a"], doc["motors"]["a"]["smoothed"]
    assert smoothed["rms_error"] == pytest.approx(true["rms_error"], rel=0.05)


def test_review_streams_the_smoothed_series_with_the_recording(
    physics_run: Path, tmp_path: Path, rrd_rows: Callable[[str | Path], Counter]
) -> None:
    from cartctl.cli.commands.review.recording import new_stream, read_recording, stream
    from cartctl.cli.commands.review.smoothed import recording_summary

    _, extra = recording_summary(physics_run / "p.rrd", GROUND)
    reader, entry = read_recording(physics_run / "p.rrd")
    rec = new_stream(entry)
    rec.save(tmp_path / "viewed.rrd")  # what a viewer would be sent, into a file
    stream(reader, entry, rec, extra=extra)
    rec.disconnect()
    rows = rrd_rows(tmp_path / "viewed.rrd")
    assert rows["motor/a/smoothed_speed"] == rows["motor/a/speed"] > 0
    assert rows["motor/b/smoothed_speed"] == rows["motor/b/speed"]


def test_a_runs_meta_file_names_its_controller_and_model(physics_run: Path) -> None:
    """run stores the controller it ran (the shipped default here) and that controller's design
    model beside its trace, so review finds the smoother's model without parsing a command."""
    from cartctl.data.trace import read_trace_meta

    meta = read_trace_meta(physics_run / "p.csv")
    assert meta is not None
    assert Path(meta.controller) == (ROOT / "controllers" / "pi.toml").resolve()
    assert Path(meta.model) == Path(GROUND).resolve()


def test_the_stop_row_does_not_bend_the_last_smoothed_speed(physics_run: Path) -> None:
    """A run's last row is its zero-volt stop command, which acts after the last measurement.
    With an nk = 1 model (the next measurement already sees a command) the smoother must not
    pull the last row's speed towards that stop."""
    from cartctl.cli.commands.review.smoothed import smoothed_speeds
    from cartctl.data.modelfile import load_models
    from cartctl.data.read import read_trace

    trace = read_trace(physics_run / "p.csv")
    columns = trace.columns()
    assert columns["voltage_a"][-1] == 0.0 and abs(columns["voltage_a"][-2]) > 1.0
    models = load_models(ROOT / "models" / "ground-timing.toml")
    assert models.motor("a").nk == 1
    smoothed = smoothed_speeds(columns, models, trace.period_s)["a"]
    error = np.abs(smoothed - columns["true_speed_a"])
    assert error[-1] <= 0.1  # rad/s, a third of a count (0.18 when it follows the stop)


def test_a_model_for_a_monitors_recording_is_refused(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A monitor's recording holds channels, not a run's motors: review shows it without metrics,
    so --model has nothing to smooth (it was silently ignored)."""
    from cartctl.sinks.rerun_sink import ChannelsRerunSink

    sink = ChannelsRerunSink("save", tmp_path / "m.rrd")
    sink.open(["time_s", "tick", "speed_a", "voltage_a", "reference_a"])
    for k in range(5):
        sink.write([k * 0.01, k, float(k), 2.0, 10.0])
    sink.close()
    shot = tmp_path / "shot.png"
    argv = ["review", str(tmp_path / "m.rrd"), "--model", GROUND, "--screenshot", str(shot)]
    code, out, err = _cli(capsys, *argv)
    assert code == 2 and out == "" and not shot.exists()
    assert len(err.strip().splitlines()) == 1 and "--model" in err and "m.rrd" in err


def test_a_runs_loop_delay_beyond_the_models_is_the_smoothers_extra_delay(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A PI designed with --extra-delay 1 on ground.toml (loop delay 1) runs in a loop of 2 ticks
    (a sim plant of nk = 3): the smoother's model is ground.toml with one tick more, not with none
    (the controller, designed for 2, matched the run, so it took 0; on the virtual cart with
    late=1 that put 1 % of overshoot on the smoothed speed that the true speed had not)."""
    text = (ROOT / "models" / "ground.toml").read_text()
    plant = tmp_path / "ground-2.toml"
    plant.write_text(
        text.replace("loop_delay_ticks = 1", "loop_delay_ticks = 2").replace("nk = 2", "nk = 3")
    )
    pi = str(tmp_path / "pi2.toml")
    assert (
        _cli(capsys, "design", GROUND, "--method", "pi", "--extra-delay", "1", "--out", pi)[0] == 0
    )
    argv = ["run", "--fast", "--plant", "sim", "--model", str(plant), "--controller", pi,
            "--duration", "1", "--noise", "0.3", "--seed", "1", "--rerun", "off",
            "--out", str(tmp_path), "--name", "r"]  # fmt: skip
    assert _cli(capsys, *argv)[0] == 0
    cart = _without_true_speed(tmp_path / "r.csv", tmp_path / "c.csv")
    (tmp_path / "c.meta.toml").write_text((tmp_path / "r.meta.toml").read_text())
    for extra in ([], ["--model", GROUND]):
        code, out, err = _cli(capsys, "review", str(cart), "--json", *extra)
        assert code == 0, err
        smoothed = json.loads(out)["smoothed"]
        assert Path(smoothed["model"]).resolve() == Path(GROUND).resolve()
        assert smoothed["extra_delay_ticks"] == 1


def test_a_trace_is_smoothed_with_its_own_runs_model_not_a_stale_recordings(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """An earlier run's RUN.rrd beside a new RUN.csv and RUN.meta.toml (a run with --rerun off
    over its name left it there before 4e1b69e; a copy can still put one there): review took the
    model from the old recording (the meta file is written with the trace, so it names this
    run's), and a monitor trace's never has one."""
    for controller, rerun in (("pi", "save"), ("poles", "off")):  # pi: ground, poles: ground-timing
        code, _, err = _cli(capsys, "run", "--fast", "--duration", "0.5", "--controller",
                            str(ROOT / "controllers" / f"{controller}.toml"), "--rerun", rerun,
                            "--out", str(tmp_path), "--name", controller)  # fmt: skip
        assert code == 0, err
    cart = _without_true_speed(tmp_path / "poles.csv", tmp_path / "cart.csv")
    (tmp_path / "poles.meta.toml").replace(tmp_path / "cart.meta.toml")
    (tmp_path / "pi.rrd").replace(tmp_path / "cart.rrd")
    code, out, err = _cli(capsys, "review", str(cart), "--json")
    assert code == 0, err
    assert Path(json.loads(out)["smoothed"]["model"]).name == "ground-timing.toml"
    with cart.open(newline="") as f:  # as a monitor's trace (no loop timing, no meta file)
        rows = list(csv.reader(f))
    keep = [i for i, name in enumerate(rows[0]) if name not in ("period_error_us", "compute_us")]
    with cart.open("w", newline="") as f:
        csv.writer(f).writerows([[row[i] for i in keep] for row in rows])
    (tmp_path / "cart.meta.toml").unlink()
    code, out, err = _cli(capsys, "review", str(cart), "--json")
    assert code == 0, err
    assert (
        json.loads(out)["trace_kind"] == "monitor" and json.loads(out)["smoothed"]["model"] is None
    )
