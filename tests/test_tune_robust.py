"""``cartctl tune --robust`` end to end, in process: a 3 × 3 PI grid over 30 sampled plants.

The grid, phase margin 65–75° × crossover 3–5 Hz, is the corner of the default PI grid
(50–75° × 2–5 Hz) where every setting is feasible on the ground model and where the nominal
overshoot is small (0–2.6 %), i.e. where a choice on the nominal figures alone is a real
temptation; one-hertz steps keep it to nine designs.

The expectations come from outside the robust code: the JSON's properties (worst case at least
the nominal, the front checked by brute force), the worst case over the sampled plants recomputed
with the real loop (``run_in_memory``) plant by plant, the physics figures against ``cartctl run
--plant physics`` of the written file, and the acceptance: the design ``--choose best`` writes
with ``--robust`` and the one it writes without (same rule, nominal figures), each run on the
physics cart with ``cartctl run``, and on the physics cart with its supply ±10 % and with one
more tick of loop delay.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cartctl.cli import main
from cartctl.data.modelfile import ModelFile, load_models, save_models
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.plants.base import Measurement
from cartctl.plants.physics import PhysicsPlant
from cartctl.plants.physics_params import preset
from cartctl.plants.sim import ArxPlant
from cartctl.reference import reference_signal
from cartctl.runtime.loop import run_in_memory
from cartctl.sinks.summary import trace_metrics
from cartctl.tune.batch import sample_plants
from cartctl.tune.engine import DelayedPlant

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
GRID = "phase_margin=65:75:5,crossover_hz=3:5:1"
PLANTS = 30
METRICS = ("overshoot_percent", "settling_time_s", "rms_error", "peak_voltage_v")


def _strict(text: str) -> Any:
    """JSON that rejects NaN and infinities (as strict parsers do)."""

    def reject(constant: str) -> None:
        raise AssertionError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=reject)


def _cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def tuned(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The robust grid with --choose best (two workers), and the same grid without --robust."""
    tmp = tmp_path_factory.mktemp("robust")
    robust, nominal, plot = tmp / "robust.toml", tmp / "nominal.toml", tmp / "robust.png"
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid", GRID, "--robust",
                          "--plants", str(PLANTS), "--seed", "1", "--jobs", "2", "--json",
                          "--choose", "best", "--out", str(robust), "--plot", str(plot))  # fmt: skip
    assert code == 0, err
    code, out_nominal, err = _cli("tune", str(GROUND), "--method", "pi", "--grid", GRID,
                                  "--jobs", "1", "--json", "--choose", "best", "--out",
                                  str(nominal))  # fmt: skip
    assert code == 0, err
    return {"doc": _strict(out), "nominal_doc": _strict(out_nominal), "robust": robust,
            "nominal": nominal, "plot": plot, "tmp": tmp}  # fmt: skip


def test_the_json_keeps_the_plain_rows_and_adds_the_robust_figures(tuned: dict[str, Any]) -> None:
    doc, plain = tuned["doc"], tuned["nominal_doc"]
    for key in ("method", "model", "plant", "reference", "duration_s", "extra_delay_ticks",
                "metrics_of", "settings", "chosen"):  # fmt: skip
        assert key in doc
    meta = doc["robust"]
    assert meta["plants"] == PLANTS and meta["seed"] == 1
    assert meta["theta_std_available"] == {"a": False, "b": False}  # the report's θ has no σ
    assert "no theta_std" in meta["theta_std_notes"]["a"]
    rows = {r["index"]: r for r in doc["settings"]}
    plain_rows = {r["index"]: r for r in plain["settings"]}
    assert sorted(rows) == list(range(1, 10))
    for index, row in rows.items():
        assert row["feasible"]
        robust = row["robust"]
        assert robust["plants"] == PLANTS
        # the row's own figures are plain tune's (the real loop on the model), and the nominal
        for key, plain_key in zip(METRICS, ("overshoot_percent", "settling_time_s", "rms_error",
                                            "peak_voltage_v"), strict=True):  # fmt: skip
            assert row[plain_key] == plain_rows[index][plain_key]
            assert robust["nominal"][key] == row[plain_key]
        for key in METRICS:
            worst = robust["worst"][key]
            if worst is None:  # a plant never settles: then the counts say so
                assert key == "settling_time_s"
                assert robust["plants_unsettled"] + robust["plants_diverged"] > 0
                continue
            assert worst >= robust["nominal"][key]
            assert robust["p5"][key] <= robust["p50"][key] <= robust["p95"][key] <= worst
        assert robust["settles_on_every_plant"] == (robust["worst"]["settling_time_s"] is not None)
        assert robust["physics"]["preset"] == "ground" and robust["physics"]["failure"] is None


def _robust_points(doc: dict[str, Any]) -> dict[int, tuple[float, float] | None]:
    points = {}
    for r in doc["settings"]:
        robust = r["robust"]
        x = None if robust is None else robust["nominal"]["settling_time_s"]
        y = None if robust is None else robust["worst"]["overshoot_percent"]
        points[r["index"]] = None if x is None or y is None else (x, y)
    return points


def test_the_robust_front_is_what_no_other_setting_dominates(tuned: dict[str, Any]) -> None:
    points = _robust_points(tuned["doc"])
    for r in tuned["doc"]["settings"]:
        mine = points[r["index"]]
        if mine is None:
            assert not r["robust"]["pareto"]
            continue
        dominated = any(
            p is not None and p[0] <= mine[0] and p[1] <= mine[1] and p != mine
            for i, p in points.items()
            if i != r["index"]
        )
        assert r["robust"]["pareto"] == (not dominated), r["index"]
    assert sum(r["robust"]["pareto"] for r in tuned["doc"]["settings"]) >= 2


def test_choose_best_takes_the_lowest_worst_case_that_settles_everywhere(
    tuned: dict[str, Any],
) -> None:
    doc = tuned["doc"]
    settled = [r for r in doc["settings"] if r["robust"]["settles_on_every_plant"]]
    lowest = min(round(r["robust"]["worst"]["overshoot_percent"], 2) for r in settled)
    ties = [r for r in settled if round(r["robust"]["worst"]["overshoot_percent"], 2) == lowest]
    best = min(ties, key=lambda r: (r["robust"]["nominal"]["settling_time_s"], r["index"]))
    assert doc["chosen"]["index"] == best["index"]
    assert "worst-case overshoot" in doc["chosen"]["rule"]
    written = load_controller(tuned["robust"]).request
    assert (written["phase_margin_deg"], written["crossover_hz"]) == (
        best["settings"]["phase-margin"],
        best["settings"]["crossover-hz"],
    )
    # without --robust the same rule runs on the nominal figures
    plain = tuned["nominal_doc"]
    nominal_best = min(
        (r for r in plain["settings"] if r["feasible"] and r["settling_time_s"] is not None),
        key=lambda r: (round(r["overshoot_percent"], 2), r["settling_time_s"], r["index"]),
    )
    assert plain["chosen"]["index"] == nominal_best["index"] != best["index"]


def test_the_worst_case_is_the_real_loops_over_the_same_plants(tuned: dict[str, Any]) -> None:
    """The chosen row's worst case over the model and the sampled plants (``worst_sampled``) and
    spread, recomputed with ``run_in_memory`` on an ``ArxPlant`` per sampled plant (the sampler
    drawn again with the same seed)."""
    doc = tuned["doc"]
    row = next(r for r in doc["settings"] if r["index"] == doc["chosen"]["index"])
    models = load_models(GROUND)
    sample = sample_plants(models, PLANTS, seed=1)
    refs = {m: reference_signal("step:10", 200, 0.01, m) for m in ("a", "b")}
    overshoot, settling = [], []
    plants = [(models.motor("a"), models.motor("b"))]
    plants += [(sample.motors["a"].model(i, 0.01), sample.motors["b"].model(i, 0.01))
               for i in range(PLANTS)]  # fmt: skip
    for a, b in plants:
        controllers = build_controllers(load_controller(tuned["robust"]))
        columns, state = run_in_memory(ArxPlant(a, b), controllers, refs, period_s=0.01,
                                       voltage_limit_v=12.0)  # fmt: skip
        assert state.failure is None
        motors = trace_metrics(columns, 0.01)["motors"].values()
        overshoot.append(max(m["overshoot_percent"] for m in motors))
        settle = [m["settling_time_s"] for m in motors]
        settling.append(math.inf if None in settle else max(settle))
    robust = row["robust"]
    sampled = robust["worst_sampled"]
    assert sampled["overshoot_percent"] == pytest.approx(max(overshoot), abs=1e-9)
    assert sampled["settling_time_s"] == pytest.approx(max(settling), abs=1e-9)
    # the worst case adds the physics cart at 3 and 10 ms (tests/test_tune_actuation.py)
    timed = [t["overshoot_percent"] for t in robust["actuation"]]
    assert [t["actuation_ms"] for t in robust["actuation"]] == [3.0, 10.0]
    assert robust["worst"]["overshoot_percent"] == max([max(overshoot), *timed])
    assert robust["p95"]["overshoot_percent"] == pytest.approx(
        np.percentile(overshoot[1:], 95, method="inverted_cdf"), abs=1e-9
    )


def _run_physics(path: Path, tmp: Path) -> dict[str, Any]:
    code, out, err = _cli("run", "--plant", "physics", "--preset", "ground", "--controller",
                          str(path), "--fast", "--duration", "2", "--rerun", "off", "--out",
                          str(tmp), "--json")  # fmt: skip
    assert code == 0, err
    return json.loads(out)


class _Supply:
    """The physics cart on a supply ``factor`` × 12 V: a command of v volts drives v·factor
    (the duty cycle is v / 12), saturated at the supply, in PWM steps of the same duty."""

    def __init__(self, factor: float) -> None:
        cart = preset("ground")
        self.plant = PhysicsPlant(dataclasses.replace(cart, supply_v=cart.supply_v * factor,
                                                      pwm_step_v=cart.pwm_step_v * factor))  # fmt: skip
        self.factor = factor
        self.period_s = self.plant.period_s

    def reset(self) -> Measurement:
        return self.plant.reset()

    def step(self, voltage_a_v: float, voltage_b_v: float) -> Measurement:
        return self.plant.step(voltage_a_v * self.factor, voltage_b_v * self.factor)

    def close(self) -> None:
        self.plant.close()


def _physics_overshoot(path: Path, factor: float, extra_ticks: int) -> float:
    plant: Any = _Supply(factor)
    if extra_ticks:
        plant = DelayedPlant(plant, extra_ticks)
    refs = {m: reference_signal("step:10", 200, 0.01, m) for m in ("a", "b")}
    columns, state = run_in_memory(plant, build_controllers(load_controller(path)), refs,
                                   period_s=0.01, voltage_limit_v=12.0)  # fmt: skip
    assert state.failure is None
    return max(m["overshoot_percent"] for m in trace_metrics(columns, 0.01)["motors"].values())


def test_acceptance_the_robust_choice_overshoots_the_physics_cart_less(
    tuned: dict[str, Any],
) -> None:
    """The issue's acceptance, three ways: the physics cart as it is (``cartctl run``); its
    supply at 90, 100 and 110 % (the DC gain ±10 %); and those with one more tick of loop delay.
    Worst case over motors a and b (and the variants)."""
    tmp = tuned["tmp"]
    runs = {k: _run_physics(tuned[k], tmp) for k in ("robust", "nominal")}
    plain = {k: max(m["overshoot_percent"] for m in r["motors"].values()) for k, r in runs.items()}
    assert plain["robust"] < plain["nominal"]
    # tune's physics figure of the chosen row is that very run
    doc = tuned["doc"]
    row = next(r for r in doc["settings"] if r["index"] == doc["chosen"]["index"])
    assert row["robust"]["physics"]["overshoot_percent"] == pytest.approx(plain["robust"], abs=1e-9)
    gains = {k: max(_physics_overshoot(tuned[k], f, 0) for f in (0.9, 1.0, 1.1)) for k in runs}
    assert gains["robust"] < gains["nominal"]
    delayed = {k: max(_physics_overshoot(tuned[k], f, 1) for f in (0.9, 1.0, 1.1)) for k in runs}
    assert delayed["robust"] < delayed["nominal"]


def test_the_table_and_the_plot(tuned: dict[str, Any]) -> None:
    assert tuned["plot"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid", GRID, "--robust",
                          "--plants", "8", "--jobs", "1")  # fmt: skip
    assert code == 0, err
    assert "8 plants drawn" in out and "no theta_std in the model file" in out
    assert "run overshoot (%)" in out and "run settling (ms)" in out and "physics run" in out
    rows = [line for line in out.splitlines() if line[5:9].strip().isdigit()]
    assert len(rows) == 9 and all(line.endswith(("settled on all", "settled on some")) for line in rows)  # fmt: skip
    assert "9 settings: 0 infeasible requests (the design refused them), 0 ran but did not" in out


def test_theta_std_from_the_file_is_used_and_the_result_is_the_same_on_one_worker(
    tmp_path: Path,
) -> None:
    ground = load_models(GROUND)
    std = [0.02, 0.015, 0.01, 0.02]
    with_std = ModelFile(ground.motors, ground.provenance, {m: {"theta_std": std} for m in "ab"})
    path = save_models(with_std, tmp_path / "model.toml")
    docs = []
    for jobs in ("1", "2"):
        code, out, err = _cli("tune", str(path), "--method", "poles", "--grid",
                              "settling_time=0.06:0.1:0.04,overshoot=1", "--robust", "--plants",
                              "12", "--seed", "9", "--duration", "1", "--jobs", jobs, "--json")  # fmt: skip
        assert code == 0, err
        docs.append(_strict(out))
    assert docs[0] == docs[1]
    meta = docs[0]["robust"]
    assert meta["theta_std_available"] == {"a": True, "b": True}
    assert meta["theta_std"]["b"] == std and "theta_std_notes" in meta
    assert meta["theta_std_notes"] == {}
    assert all(r["robust"] is not None for r in docs[0]["settings"])


def test_plants_that_never_settle_give_a_null_worst_case_and_say_so() -> None:
    """A 0.6 s run: the step at 0.5 s leaves 10 ticks, too few for the slow plants to settle."""
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--grid",
                          "phase_margin=65,crossover_hz=4", "--robust", "--plants", "10",
                          "--duration", "0.6", "--jobs", "1", "--json")  # fmt: skip
    assert code == 0, err
    robust = _strict(out)["settings"][0]["robust"]
    assert robust["worst"]["settling_time_s"] is None
    assert robust["plants_unsettled"] > 0 and robust["plants_diverged"] == 0
    assert robust["settles_on_every_plant"] is False and robust["pareto"] is True
    assert robust["worst"]["overshoot_percent"] >= robust["nominal"]["overshoot_percent"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [(["--robust", "--plants", "0"], "--plants must be"),
     (["--seed", "3"], "--seed only apply to --robust"),
     (["--plants", "3"], "--plants only apply to --robust"),
     (["--robust", "--plant", "physics"], "leave out --plant physics"),
     (["--choose", "most", "--out", "x.toml"], "--choose takes a setting number or 'best'"),
     (["--choose", "0", "--out", "x.toml"], "--choose must be a setting number in 1..1"),
     (["--robust", "--plants", "5000", "--duration", "5"], "use fewer --plants"),
     (["--grid", "phase_margin=50,crossover_hz=2", "--choose", "best", "--out", "x.toml"],
      "no feasible setting settles"),
     (["--grid", "phase_margin=50,crossover_hz=2", "--robust", "--plants", "2", "--choose",
       "best", "--out", "x.toml"], "no feasible setting settles on every sampled plant")],
)  # fmt: skip
def test_bad_robust_input_is_one_line_and_exit_2(
    argv: list[str], message: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    grid = [] if "--grid" in argv else ["--grid", "phase_margin=65,crossover_hz=4"]
    code, out, err = _cli("tune", str(GROUND), "--method", "pi", "--jobs", "1", "--duration",
                          "0.6", *grid, *argv)  # fmt: skip
    assert code == 2
    if "best" in argv:  # the results were computed: the table, then the error
        assert "1 setting: 1 infeasible request (the design refused it)" in out
    else:
        assert out == ""
    assert err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "x.toml").exists()
