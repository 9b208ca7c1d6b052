"""Measure the shipped controllers on the plants they are for: step, settling bound, estimator.

Usage::

    python benchmarks/measure_shipped.py                  # controllers/{pi,poles,serial-pi,serial-poles}.toml
    python benchmarks/measure_shipped.py --no-virtual     # skip the real-time serial runs
    python benchmarks/measure_shipped.py --controllers DIR --json

Every number comes from ``cartctl run`` itself (a subprocess, ``--rerun off``), read back from the
trace it writes. For each controller file and each plant that has the controller's loop delay:

- ``sim``: the ARX cart on the controller's own model where its nk fits the file's loop delay
  (nk = loop delay or loop delay + 1), else on a copy moved to nk = loop delay + 1 (a serial
  controller designed on an on-board model);
- ``physics`` and ``physics:actuation_ms=10``: the physical simulator, loop delay 1 (on-board
  controllers only), with each command landing 3 ms after its tick (the presets' calibrated
  timing) and 10 ms after it (microOS's documented order, the next tick's ``io()``): a real cart's
  timing is unknown, so the on-board files are measured at both ends;
- ``virtual``: the physical simulator behind the serial link, in real time (serial controllers
  only; the virtual cart hands the simulator's true speed to the trace as well). Since bridge
  version 2 the serial loop's delay is 1, as on board, and ``run`` refuses these loop-delay-3
  files there in one line, which is reported as a failure.

Step (``--reference step:10``, 2 s): overshoot and settling of each motor's *true* speed where the
plant gives one, in the band max(2 % of the step, one encoder count per tick = 0.3506 rad/s), and
the settling time as a multiple of the time-optimal bound
(:func:`cartctl.design.analysis.settling_bound`) on the model with the same loop delay.

Estimator (``--reference square:8:2``, 10 s, plants with a true speed): RMS(estimate − true speed)
divided by RMS(measured speed − true speed), over the whole run and over the steady windows alone
(the second half of every stretch of constant reference: the last 0.5 s of each 1 s level). Below 1
the estimate is closer to the true speed than the encoder; a controller without an estimator logs
the measurement as its estimate, so its ratio is 1. On ``sim`` the true speed is the model's output,
itself a tick average like the measurement, and without ``--noise`` equal to it (no ratio).

The script exits with 1 when a run fails (it prints the run's error line).
"""

from __future__ import annotations

import argparse
import itertools
import json
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
try:
    from cartctl.cart import encoder_quantum_rad_s
    from cartctl.data.modelfile import load_models, save_models
    from cartctl.data.read import read_trace
    from cartctl.design.analysis import settling_bound
    from cartctl.design.controllerfile import load_controller
    from cartctl.measures.stepinfo import step_info
    from cartctl.model import ArxModel
except ModuleNotFoundError:  # not installed: run from a checkout
    sys.path.insert(0, str(ROOT / "src"))
    from cartctl.cart import encoder_quantum_rad_s
    from cartctl.data.modelfile import load_models, save_models
    from cartctl.data.read import read_trace
    from cartctl.design.analysis import settling_bound
    from cartctl.design.controllerfile import load_controller
    from cartctl.measures.stepinfo import step_info
    from cartctl.model import ArxModel

SHIPPED = ("pi", "poles", "serial-pi", "serial-poles")
PHYSICS_TIMINGS = ("physics", "physics:actuation_ms=10")
"""The physics plants of the on-board files: the command landing 3 ms (the preset) and 10 ms
after its tick."""
STEP_RAD_S = 10.0
STEP_AT_S = 0.5
QUANTUM_RAD_S = encoder_quantum_rad_s(0.01)
"""One encoder count per tick (rad/s): the narrowest settling band."""


def run(args: list[str], out: Path, name: str) -> tuple[dict[str, np.ndarray] | None, str]:
    """``cartctl run ARGS`` into ``out``; (trace columns, '') or (None, the error line)."""
    cmd = [sys.executable, "-m", "cartctl", "run", *args, "--rerun", "off", "--out", str(out),
           "--name", name, "--json"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if proc.returncode != 0:
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        return None, lines[-1] if lines else f"exit code {proc.returncode}"
    return read_trace(out / f"{name}.csv").columns(), ""


def step_numbers(trace: dict[str, np.ndarray], motor: str) -> dict[str, Any]:
    """Overshoot (%) and settling (s) of one motor's step, on the true speed where there is one."""
    column = f"true_speed_{motor}" if f"true_speed_{motor}" in trace else f"speed_{motor}"
    info = step_info(trace["time_s"], trace[column], reference=STEP_RAD_S, onset_s=STEP_AT_S,
                     settling_floor=QUANTUM_RAD_S)  # fmt: skip
    return {"overshoot_percent": info.overshoot_percent, "settling_time_s": info.settling_time_s,
            "on": column}  # fmt: skip


def steady_mask(reference: np.ndarray) -> np.ndarray:
    """True in the second half of every stretch of constant reference."""
    mask = np.zeros(reference.size, dtype=bool)
    edges = np.r_[0, np.flatnonzero(np.diff(reference) != 0.0) + 1, reference.size]
    for start, end in itertools.pairwise(edges):
        mask[start + (end - start) // 2 : end] = True
    return mask


def estimator_ratios(trace: dict[str, np.ndarray], motor: str) -> dict[str, Any]:
    """RMS(estimate − true) / RMS(measured − true), whole run and steady windows."""
    true = trace.get(f"true_speed_{motor}")
    if true is None:
        return {"whole": None, "steady": None}
    est, meas = trace[f"estimate_{motor}"], trace[f"speed_{motor}"]
    steady = steady_mask(trace[f"reference_{motor}"])

    def ratio(mask: np.ndarray) -> float | None:
        encoder = float(np.sqrt(np.mean((meas[mask] - true[mask]) ** 2)))
        if encoder == 0.0:  # a noise-free sim: the measurement is the true speed
            return None
        return float(np.sqrt(np.mean((est[mask] - true[mask]) ** 2))) / encoder

    return {"whole": ratio(np.ones(true.size, dtype=bool)), "steady": ratio(steady)}


def _file_name(plant: str) -> str:
    """A plant name as part of a trace's file name ('physics:actuation_ms=10' -> 'physics-10ms')."""
    kind, _, options = plant.partition(":")
    return kind if not options else f"{kind}-{options.partition('=')[2]}ms"


def on_loop(model: ArxModel, delay: int) -> ArxModel:
    """The model for a loop of ``delay`` ticks: itself where its nk fits that loop
    (:func:`cartctl.cart.nk_fits_loop_delay`: nk = delay, or delay + 1), else moved to
    nk = delay + 1."""
    from cartctl.cart import nk_fits_loop_delay

    if nk_fits_loop_delay(model.nk, delay):
        return model
    return model.with_extra_delay(delay + 1 - model.nk)


def measure(path: Path, out: Path, virtual: bool) -> tuple[list[dict[str, Any]], list[str]]:
    """Rows (one per plant and motor) for one controller file, and the failures."""
    controller = load_controller(path)
    models = load_models(controller.model_path)
    nk = {m: models.motor(m).nk for m in ("a", "b")}
    delay = controller.loop_delay_ticks  # load_controller derives it for older files
    assert delay is not None
    plants: list[tuple[str, list[str], bool]] = []
    if all(on_loop(models.motor(m), delay) == models.motor(m) for m in nk):
        plants.append(("sim", ["--plant", "sim", "--model", str(controller.model_path), "--fast"],
                       True))  # fmt: skip
    else:
        delayed = out / f"{path.stem}-model.toml"
        save_models(replace(models, motors={m: on_loop(models.motor(m), delay) for m in "ab"}),
                    delayed)  # fmt: skip
        plants.append(("sim", ["--plant", "sim", "--model", str(delayed), "--fast"], True))
    if delay == 1:
        for spec in PHYSICS_TIMINGS:
            plants.append((spec, ["--plant", spec, "--fast"], True))
    if controller.loop_site == "serial" and virtual:
        plants.append(("virtual", ["--plant", "virtual"], True))
    rows, failures = [], []
    for plant, plant_args, has_true in plants:
        common = ["--controller", str(path), *plant_args]
        step, problem = run([*common, "--reference", f"step:{STEP_RAD_S:g}", "--duration", "2"],
                            out, f"{path.stem}-{_file_name(plant)}-step")  # fmt: skip
        if step is None:
            failures.append(f"{path.name} on {plant}: {problem}")
            continue
        square = None
        if has_true:
            square, problem = run([*common, "--reference", "square:8:2", "--duration", "10"],
                                  out, f"{path.stem}-{_file_name(plant)}-square")  # fmt: skip
            if square is None:
                failures.append(f"{path.name} on {plant} (square): {problem}")
        for motor in ("a", "b"):
            model = on_loop(models.motor(motor), delay)
            bound = settling_bound(model, STEP_RAD_S).settling_time_s
            numbers = step_numbers(step, motor)
            settle = numbers["settling_time_s"]
            rows.append({
                "controller": path.name, "plant": plant, "motor": motor, "loop_delay_ticks": delay,
                **numbers, "bound_s": bound,
                "ratio_to_bound": None if settle is None else settle / bound,
                "estimator_rms_ratio": estimator_ratios(square, motor) if square else
                {"whole": None, "steady": None},
            })  # fmt: skip
    return rows, failures


def table(rows: list[dict[str, Any]]) -> str:
    def num(x: float | None, fmt: str) -> str:
        return "—" if x is None else format(x, fmt)

    width = max([len("plant"), *(len(r["plant"]) for r in rows)]) + 2
    head = (f"{'controller':<19}{'plant':<{width}}{'m':<3}{'delay':>6}{'overshoot':>11}"
            f"{'settling':>10}{'bound':>8}{'ratio':>7}{'est/enc':>9}{'steady':>8}  on")  # fmt: skip
    lines = [head, "-" * len(head)]
    for r in rows:
        settle = r["settling_time_s"]
        est = r["estimator_rms_ratio"]
        lines.append(
            f"{r['controller']:<19}{r['plant']:<{width}}{r['motor']:<3}{r['loop_delay_ticks']:>6}"
            f"{num(r['overshoot_percent'], '.1f') + ' %':>11}"
            f"{('—' if settle is None else f'{settle * 1e3:.0f} ms'):>10}"
            f"{r['bound_s'] * 1e3:>6.0f}ms{num(r['ratio_to_bound'], '.2f'):>7}"
            f"{num(est['whole'], '.2f'):>9}{num(est['steady'], '.2f'):>8}  {r['on']}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--controllers", default=str(ROOT / "controllers"), metavar="DIR")
    parser.add_argument("--no-virtual", action="store_true", help="skip the real-time serial runs")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the table")
    args = parser.parse_args(argv)
    rows: list[dict[str, Any]] = []
    failures: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in SHIPPED:
            path = Path(args.controllers) / f"{name}.toml"
            if not path.is_file():
                failures.append(f"{path}: no such file")
                continue
            got, failed = measure(path.resolve(), Path(tmp), virtual=not args.no_virtual)
            rows += got
            failures += failed
    if args.json:
        print(json.dumps({"rows": rows, "failures": failures}))
    else:
        print(table(rows))
        for problem in failures:
            print(f"failed: {problem}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
