"""Plants drawn around a model file (``cartctl.tune.batch``): properties of the draws.

Checked against the model file itself and numpy's roots, never against the sampler's own output:
θ moves within ±theta_std, the b coefficients carry a gain factor in [0.9, 1.1], the delay moves by
at most one tick and never below 1, every plant is stable, a seed reproduces the plants, and a file
without theta_std leaves θ alone and says so.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cartctl.data.modelfile import ModelFile, Provenance, load_models
from cartctl.errors import InputError
from cartctl.model import ArxModel
from cartctl.tune.batch import sample_plants

GROUND = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
STD = [0.02, 0.015, 0.01, 0.02]  # about what identify gives on 25 s of square-wave data


def _with_std(std: list[float] | None = None, nk: int = 2) -> ModelFile:
    ground = load_models(GROUND)
    motors = {m: ArxModel(ground.motor(m).ar, ground.motor(m).b, nk) for m in ("a", "b")}
    stats = {} if std is None else {m: {"theta_std": list(std)} for m in ("a", "b")}
    return ModelFile(motors, Provenance("test", "2024-01-01"), stats)


def _largest_pole(ar: np.ndarray) -> float:
    return float(np.max(np.abs(np.roots(np.concatenate([[1.0], ar])))))


def test_draws_stay_within_the_stated_ranges_and_are_stable() -> None:
    models = _with_std(STD)
    sample = sample_plants(models, 400, seed=3)
    assert sample.size == 400
    shifts = sample.delay_shift_ticks
    assert set(shifts.tolist()) == {-1, 0, 1}
    for name in ("a", "b"):
        model, s = models.motor(name), sample.motors[name]
        theta0 = model.theta
        gain = s.gain_factor
        assert np.all((gain >= 0.9) & (gain <= 1.1))
        ar_delta = s.ar - theta0[:2]
        b_delta = s.b / gain[:, None] - theta0[2:]
        assert np.all(np.abs(ar_delta) <= np.array(STD[:2]) + 1e-15)
        assert np.all(np.abs(b_delta) <= np.array(STD[2:]) + 1e-12)
        np.testing.assert_array_equal(s.nk, 2 + shifts)  # both motors share the loop's delay
        assert all(_largest_pole(ar) < 1.0 for ar in s.ar)
        # the model is stable in the middle of the draws: none needed redrawing here
        assert s.rejected_unstable == 0


def test_draws_are_uniform_within_one_standard_deviation() -> None:
    """δ/σ spreads over [−1, 1] with the moments of a uniform law (mean 0, variance 1/3)."""
    sample = sample_plants(_with_std(STD), 4000, seed=5)
    for s in sample.motors.values():
        unit = s.theta_delta / np.array(STD)
        assert np.all(np.abs(unit) <= 1.0)
        assert np.all(np.abs(unit.mean(axis=0)) < 0.05)
        assert np.all(np.abs(unit.var(axis=0) - 1.0 / 3.0) < 0.03)
        assert np.all(unit.max(axis=0) > 0.99) and np.all(unit.min(axis=0) < -0.99)
        assert np.abs(s.gain_factor.mean() - 1.0) < 0.005
    counts = np.bincount(sample.delay_shift_ticks + 1, minlength=3) / 4000
    assert np.all(np.abs(counts - 1 / 3) < 0.03)


def test_a_seed_gives_the_same_plants_and_another_seed_others() -> None:
    models = _with_std(STD)
    one, again, other = (sample_plants(models, 50, seed=s) for s in (7, 7, 8))
    for m in ("a", "b"):
        np.testing.assert_array_equal(one.motors[m].ar, again.motors[m].ar)
        np.testing.assert_array_equal(one.motors[m].b, again.motors[m].b)
        assert not np.array_equal(one.motors[m].b, other.motors[m].b)
    np.testing.assert_array_equal(one.delay_shift_ticks, again.delay_shift_ticks)


def test_a_file_without_theta_std_keeps_theta_and_says_so() -> None:
    models = load_models(GROUND)
    sample = sample_plants(models, 60, seed=1)
    described = sample.describe()
    assert described["theta_std_available"] == {"a": False, "b": False}
    assert described["theta_std"] == {"a": None, "b": None}
    assert "no theta_std" in described["theta_std_notes"]["a"]
    for name in ("a", "b"):
        model, s = models.motor(name), sample.motors[name]
        np.testing.assert_array_equal(s.ar, np.tile(model.ar, (60, 1)))
        np.testing.assert_allclose(s.b, np.outer(s.gain_factor, model.b), rtol=1e-15)


@pytest.mark.parametrize(
    ("std", "why"),
    [([0.01, 0.01], "has 2 values"), ([0.01, float("nan"), 0.01, 0.01], "not finite"),
     ([0.01, -0.01, 0.01, 0.01], ">= 0"), ("wide", "not a list")],
)  # fmt: skip
def test_an_unusable_theta_std_is_not_used_and_the_reason_given(std: object, why: str) -> None:
    ground = load_models(GROUND)
    models = ModelFile(ground.motors, ground.provenance, {"a": {"theta_std": std}})
    sample = sample_plants(models, 10, seed=1)
    assert sample.motors["a"].theta_std is None
    assert why in sample.motors["a"].theta_std_note
    np.testing.assert_array_equal(sample.motors["a"].theta_delta, 0.0)


def test_the_delay_never_drops_below_one_tick() -> None:
    sample = sample_plants(_with_std(STD, nk=1), 300, seed=2)
    nk = sample.motors["a"].nk
    assert nk.min() == 1 and nk.max() == 2
    np.testing.assert_array_equal(nk, np.maximum(1, 1 + sample.delay_shift_ticks))


def test_extra_delay_moves_the_whole_range() -> None:
    sample = sample_plants(load_models(GROUND), 300, seed=2, extra_delay_ticks=2)
    np.testing.assert_array_equal(sample.motors["b"].nk, 4 + sample.delay_shift_ticks)


def test_unstable_draws_are_redrawn_and_counted() -> None:
    """z² + c z + d has a root outside the unit circle when |c| ≥ 1 + d: the ground model's
    c = −0.9356, d = 0.2173 with σ 0.3 and 0.2 gets there in some draws."""
    sample = sample_plants(_with_std([0.3, 0.2, 0.01, 0.01]), 300, seed=4)
    for s in sample.motors.values():
        assert s.rejected_unstable > 0
        assert all(_largest_pole(ar) < 1.0 for ar in s.ar)


def test_hopeless_uncertainty_and_bad_counts_are_one_line_errors() -> None:
    # σ = 50 on c and d: the stable triangle (area 4) is 0.04 % of the box of draws
    with pytest.raises(InputError, match="unstable"):
        sample_plants(_with_std([50.0, 50.0, 0.0, 0.0]), 20, seed=1)
    with pytest.raises(InputError, match="--plants"):
        sample_plants(load_models(GROUND), 0, seed=1)
    # (z − 1)(z − 0.5): an integrator, marginally stable; (z − 2)(z − 0.5): unstable
    for ar, word in (((-1.5, 0.5), "marginally stable"), ((-2.5, 1.0), "is unstable")):
        model = ModelFile({m: ArxModel(ar, (1.0,), 1) for m in ("a", "b")},
                          Provenance("test", "2024-01-01"))  # fmt: skip
        with pytest.raises(InputError, match=word):
            sample_plants(model, 5, seed=1)
