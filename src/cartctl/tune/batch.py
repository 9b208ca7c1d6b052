"""N ARX plants at once for ``cartctl tune --robust``: drawn from a model file's uncertainty
(:func:`sample_plants`; one generator seeded with ``--seed`` in a fixed order, so a seed gives the
same plants whatever the worker count), then run against one designed controller in one loop over
the ticks, each quantity an array over the plants (:func:`simulate_batch`: operation for operation
what ``cartctl run --fast`` does with one motor of an ``ArxPlant`` without noise). The draw and
the loop in words: docs/tuning.md."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cartctl.cart import SUPPLY_V, check_voltage_limit
from cartctl.data.modelfile import ModelFile
from cartctl.errors import InputError
from cartctl.model import ArxModel, check_input_delay
from cartctl.plants.sim import DIVERGED_RAD_S, arx_next
from cartctl.runtime.base import Controller
from cartctl.runtime.elementwise import clip
from cartctl.runtime.kalman import (
    FilterTerms,
    SteadyStateSpeedEstimator,
    filter_correct,
    filter_predict,
)
from cartctl.runtime.pi import PiController, pi_law
from cartctl.runtime.statefeedback import StateFeedbackController, feedback_law

FloatArray = NDArray[np.float64]
GAIN_RANGE = (0.9, 1.1)
DELAY_SHIFTS_TICKS = (-1, 0, 1)
MAX_DRAWS_PER_PLANT = 100  # θ draws per plant on average before giving up on stable ones


@dataclass(frozen=True)
class ArxBatch:
    """N ARX plants of one motor: ``ar`` (N, na) and ``b_lags`` (N, L), the coefficient of u[k − l]
    in y[k + 1] (b_i at l = nk − 1 + i, else 0; rad/s per V), and Ts (s); their commands saturate
    at the supply, as :class:`~cartctl.plants.sim.ArxPlant`'s."""

    ar: FloatArray
    b_lags: FloatArray
    period_s: float

    @classmethod
    def from_arrays(
        cls, ar: ArrayLike, b: ArrayLike, nk: ArrayLike, *, period_s: float
    ) -> ArxBatch:
        """From ``ar`` (N, na), ``b`` (N, nb) and input delays ``nk`` (N,) ≥ 1."""
        b_arr, nk_arr = np.asarray(b, dtype=float), np.asarray(nk, dtype=int)
        (n, nb), nk_max = b_arr.shape, int(nk_arr.max(initial=1))
        if n:
            check_input_delay(int(nk_arr.min()))
        lags = np.zeros((n, nk_max - 1 + nb))
        np.put_along_axis(lags, nk_arr[:, None] - 1 + np.arange(nb), b_arr, axis=1)
        return cls(np.asarray(ar, dtype=float), lags, float(period_s))

    @classmethod
    def from_models(cls, models: Sequence[ArxModel]) -> ArxBatch:
        """From ARX models of equal orders and period (their delays may differ)."""
        if len({(m.na, m.nb, m.period_s) for m in models}) != 1:
            raise InputError("the models of a plant batch must share na, nb and the period")
        columns = ([m.ar for m in models], [m.b for m in models], [m.nk for m in models])
        return cls.from_arrays(*columns, period_s=models[0].period_s)


@dataclass(frozen=True)
class BatchTrace:
    """One motor's traces over N plants, as ``cartctl run`` logs them (n ticks, then the stop row).
    ``time_s`` and ``reference`` (n + 1,) in s and rad/s; ``speed`` (N, n + 1), the measured and
    true speed (rad/s); ``voltage`` (N, n + 1), the command sent (V, 0 in the stop row);
    ``diverged`` (N,), the plants that ran away."""

    time_s: FloatArray
    reference: FloatArray
    speed: FloatArray
    voltage: FloatArray
    diverged: NDArray[np.bool_]


def _filter_terms(est: object) -> FilterTerms:
    if isinstance(est, SteadyStateSpeedEstimator):
        return est.terms
    raise InputError(
        f"the batch loop runs the fixed-gain estimator only, not {type(est).__name__} (a design "
        "with timing noise, timing_noise_std_ticks > 0, has a gain that depends on the commands)"
    )


def simulate_batch(
    controller: Controller,
    plants: ArxBatch,
    reference: ArrayLike,
    *,
    voltage_limit_v: float = SUPPLY_V,
) -> BatchTrace:
    """Run ``controller``'s design (read only: gains, limit, anti-windup, estimator) against every
    plant from rest, with the loop's clamp ``voltage_limit_v`` (V), following ``reference`` (rad/s,
    one value per tick)."""
    ref = np.asarray(reference, dtype=float)
    loop_lim = check_voltage_limit(voltage_limit_v)
    c = controller
    if not isinstance(c, PiController | StateFeedbackController):
        raise InputError(f"the batch loop does not know the controller {type(c).__name__}")
    n_ticks, n = ref.size, plants.b_lags.shape[0]
    # the controller's runtime law (pi_law or feedback_law) over the plants, inside its estimator
    est = None if c.estimator is None else _filter_terms(c.estimator)
    x = [np.zeros(n) for _ in (est.L if est else ())]
    integral = np.zeros(n)
    na, width = plants.ar.shape[1], plants.b_lags.shape[1]
    ar, b_lags = list(plants.ar.T), list(plants.b_lags.T)
    # row width − 1 + k of u_hist is u[k] as the plant applies it, row na + k of y_hist is y[k]
    # (one column per plant), zeros before tick 0 (rest); voltage[:, k] is u[k] as sent and logged
    u_hist = np.zeros((width - 1 + n_ticks, n))
    y_hist = np.zeros((na + n_ticks + 1, n))
    voltage = np.zeros((n, n_ticks + 1))
    diverged = np.zeros(n, dtype=bool)
    with np.errstate(all="ignore"):
        for k in range(n_ticks):
            r, y = float(ref[k]), y_hist[na + k]
            if est is not None:
                x = filter_correct(est, x, y)
            if isinstance(c, PiController):
                error = r - (y if est is None else x[0])
                u, integral = pi_law(error, integral, *c.gains, c.voltage_limit_v)
            else:
                u_raw, u, integral = feedback_law(r, y, x, integral, c.terms, c.voltage_limit_v)
                u = np.where(np.isfinite(u_raw), u, 0.0)
            if est is not None:
                x = filter_predict(est, x, u)
            u = clip(np.where(np.isfinite(u), u, 0.0), loop_lim)
            voltage[:, k] = u
            base = width - 1 + k
            u_hist[base] = clip(u, SUPPLY_V)
            y_next = arx_next(b_lags, u_hist[base::-1], 0, ar, y_hist[na + k :: -1])
            diverged |= ~(np.abs(y_next) < DIVERGED_RAD_S)
            y_next[diverged] = 0.0
            y_hist[na + k + 1] = y_next
    period = plants.period_s
    time_s = np.arange(n_ticks + 1, dtype=np.float64) * period
    time_s[-1] = time_s[-2] + period  # the stop row: the last tick's time + Ts, as the loop logs it
    return BatchTrace(time_s, np.append(ref, ref[-1]), np.ascontiguousarray(y_hist[na:].T),
                      voltage, diverged)  # fmt: skip


@dataclass(frozen=True)
class MotorSamples:
    """The sampled models of one motor: ``ar`` (N, na), ``b`` (N, nb, the gain factor applied),
    ``nk`` (N,), ``gain_factor`` g and ``theta_delta`` δ per plant, the σ used (None when the file
    has no usable one, ``theta_std_note`` saying why) and the count of unstable draws rejected."""

    ar: NDArray[np.float64]
    b: NDArray[np.float64]
    nk: NDArray[np.int_]
    gain_factor: NDArray[np.float64]
    theta_delta: NDArray[np.float64]
    theta_std: NDArray[np.float64] | None
    theta_std_note: str | None
    rejected_unstable: int

    def model(self, i: int, period_s: float) -> ArxModel:
        """Plant ``i`` as an :class:`~cartctl.model.ArxModel`."""
        return ArxModel(tuple(self.ar[i]), tuple(self.b[i]), int(self.nk[i]), period_s)


@dataclass(frozen=True)
class PlantSample:
    """N plants drawn around a model file: per motor samples, each plant's delay shift s, the seed,
    Ts."""

    motors: dict[str, MotorSamples]
    delay_shift_ticks: NDArray[np.int_]
    seed: int
    period_s: float

    @property
    def size(self) -> int:
        return int(self.delay_shift_ticks.size)

    def describe(self) -> dict[str, Any]:
        """The sampling for ``--json``."""
        motors = self.motors.items()
        return {"plants": self.size, "seed": self.seed,
                "theta": "θ + δ, δ ~ uniform[−σ, +σ] per entry (σ: the model file's theta_std)",
                "dc_gain_factor": {"distribution": "uniform", "range": list(GAIN_RANGE),
                                   "per": "motor"},
                "delay_shift_ticks": {"values": list(DELAY_SHIFTS_TICKS), "per": "plant",
                                      "minimum_nk": 1},
                "theta_std": {m: None if s.theta_std is None else s.theta_std.tolist()
                              for m, s in motors},
                "theta_std_available": {m: s.theta_std is not None for m, s in motors},
                "theta_std_notes": {m: s.theta_std_note for m, s in motors if s.theta_std_note},
                "rejected_unstable": {m: s.rejected_unstable for m, s in motors}}  # fmt: skip


def theta_std_of(model: ArxModel, stats: Mapping[str, Any]) -> tuple[NDArray[np.float64] | None, str | None]:  # fmt: skip
    """A motor's σ of θ from its model-file ``stats``: (σ, None), or (None, why not); σ must be
    na + nb finite numbers ≥ 0 (an output-error fit with a singular Jacobian writes NaN)."""
    raw = stats.get("theta_std")
    if raw is None:
        return None, "no theta_std in the model file: θ kept as it is"
    try:
        std = np.asarray(raw, dtype=float).ravel()
    except (TypeError, ValueError):
        return None, f"theta_std is not a list of numbers ({raw!r}): θ kept as it is"
    p = model.na + model.nb
    if std.size != p:
        return None, f"theta_std has {std.size} values, θ has {p}: θ kept as it is"
    if not (np.all(np.isfinite(std)) and np.all(std >= 0.0)):
        return None, "theta_std holds values that are not finite numbers >= 0: θ kept as it is"
    return std, None


def _stable(ar: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per row of a_1 … a_na: every root of z^na + a_1 z^(na−1) + … + a_na inside |z| < 1."""
    n, na = ar.shape
    if na == 0:
        return np.ones(n, dtype=bool)
    companion = np.zeros((n, na, na))
    companion[:, 0, :] = -ar
    companion[:, np.arange(1, na), np.arange(na - 1)] = 1.0  # (nothing for na = 1)
    return np.max(np.abs(np.linalg.eigvals(companion)), axis=1) < 1.0


def _sample_motor(
    rng: np.random.Generator,
    model: ArxModel,
    stats: Mapping[str, Any],
    nk: NDArray[np.int_],
    name: str,
) -> MotorSamples:
    n, p = nk.size, model.na + model.nb
    std, note = theta_std_of(model, stats)
    theta0, sigma = model.theta, np.zeros(p) if std is None else std
    gain = rng.uniform(*GAIN_RANGE, size=n)
    delta, rejected = np.zeros((n, p)), 0
    todo = np.full(n, std is not None)  # the plants to draw: all, then those drawn unstable
    while todo.any():
        idx = np.flatnonzero(todo)
        delta[idx] = rng.uniform(-1.0, 1.0, size=(idx.size, p)) * sigma
        todo[idx] = ~_stable((theta0 + delta[idx])[:, : model.na])
        rejected += int(todo.sum())
        if rejected > MAX_DRAWS_PER_PLANT * n:
            raise InputError(
                f"motor {name}: {rejected} of the θ draws within ±theta_std were unstable; "
                "the model's uncertainty does not describe a stable motor"
            )
    theta = theta0 + delta
    return MotorSamples(ar=theta[:, : model.na], b=theta[:, model.na :] * gain[:, None], nk=nk,
                        gain_factor=gain, theta_delta=delta, theta_std=std,
                        theta_std_note=note, rejected_unstable=rejected)  # fmt: skip


def sample_plants(
    models: ModelFile, n_plants: int, seed: int, *, extra_delay_ticks: int = 0
) -> PlantSample:
    """Draw ``n_plants`` ≥ 1 plants around ``models`` with ``seed``, for ``extra_delay_ticks``
    beyond the model's delay; refuses a missing or unstable model and a σ so large that stable draws
    are too rare."""
    if isinstance(n_plants, bool) or not isinstance(n_plants, int) or n_plants < 1:
        raise InputError(f"--plants must be a number of plants >= 1, got {n_plants!r}")
    for name in ("a", "b"):
        model = models.motor(name)
        if not model.is_stable():
            raise InputError(
                f"motor {name}'s model is {model.stability()} (a pole at |z| = {model.pole_radius():.4g}): "
                "plants drawn around it cannot be held to stable ones"
            )
    rng = np.random.default_rng(seed)
    shifts = rng.choice(np.array(DELAY_SHIFTS_TICKS), size=n_plants)
    motors: dict[str, MotorSamples] = {}
    for name in ("a", "b"):
        model = models.motor(name)
        nk = np.maximum(1, model.nk + extra_delay_ticks + shifts)
        motors[name] = _sample_motor(rng, model, models.stats.get(name, {}), nk, name)
    return PlantSample(motors, shifts, int(seed), models.period_s)


def describe_line(sample: PlantSample, model_path: str) -> str:
    """One line for the terminal: how the plants were drawn, and what the file lacked."""
    drawn = "θ ± σ (uniform; {} unstable draws redrawn)"  # else the note says why not
    theta = [
        f"motor {m}: {s.theta_std_note or drawn.format(s.rejected_unstable)}"
        for m, s in sample.motors.items()
    ]
    lo, hi = GAIN_RANGE
    return (f"{sample.size} plants drawn around {model_path} (seed {sample.seed}): "
            + "; ".join(theta) + f"; DC gain × uniform[{lo:g}, {hi:g}] per motor; loop delay "
            "moved by −1, 0 or +1 tick per plant (nk at least 1)")  # fmt: skip


def later_command(model: ArxModel, fraction: float) -> ArxModel:
    """``model`` with every command landing ``fraction`` f ∈ [0, 1] of a tick later: the motor sees
    the previous command for f of the tick, so to first order in the tick (the motor slow against
    Ts) the tick's speed answers (1 − f)·u(k) + f·u(k − 1): B(z)·((1 − f) + f z⁻¹), same poles,
    delay and DC gain, the phase lag of f ticks at low frequency (docs/commission.md)."""
    f = float(fraction)
    if not 0.0 <= f <= 1.0:
        raise InputError(f"a command can land 0 to 1 tick later here, got {fraction}")
    b = np.asarray(model.b, dtype=float)
    blended = (1.0 - f) * np.append(b, 0.0) + f * np.insert(b, 0, 0.0)
    return ArxModel(tuple(model.ar), tuple(blended), model.nk, model.period_s)
