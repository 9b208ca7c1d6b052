"""Models and controllers as MATLAB ``.mat`` files (``cartctl export --mat FILE.mat``).

Where it sits: after ``identify`` (a model file) or ``design`` (a controller file). The contents
are built here as plain dicts of numpy arrays (pure); :func:`write_mat` writes them with
:func:`scipy.io.savemat` (MATLAB 5 format, which MATLAB, Octave and scipy read). Each motor is a
struct ``motor_a`` / ``motor_b``; the sample period is ``Ts`` (s) at the top level and in each
struct. Transfer functions are in descending powers of z, as MATLAB's ``tf(num, den, Ts)`` and
python-control's ``control.tf`` take them.

A model file gives, per motor: ``num``, ``den`` (V → rad/s, the input delay nk in ``den``),
``theta`` (the report's [c, d, a, b] order: a_1 … a_na, b_0 … b_{nb−1}), ``theta_std`` (empty
when the file has none), ``na``, ``nb``, ``nk``, ``Ts``.

A controller file gives, per motor, the controller as the loop runs it
(:mod:`cartctl.design.controller_ss`): ``A``, ``B``, ``C``, ``D`` of ``s⁺ = A s + B [r; y]``,
``u = C s + D [r; y]`` (r the reference and y the measured speed in rad/s, u the voltage in V;
``states`` names the states), ``feedback_num``/``feedback_den`` of C_fb = −U/Y (the loop is
L = C_fb·G·z^(−extra) with negative feedback), the gains (``kp``, ``ki`` for a PI in V/(rad/s)
and V/rad; ``K``, ``Ki``, ``Kr`` for pole placement), the estimator's ``L`` and matrices when there
is one, and at the top level ``Ts``, ``loop_delay_ticks``, ``extra_delay_ticks``,
``voltage_limit_v`` and ``method``. The voltage limit and anti-windup are not in A, B, C, D.

In MATLAB::

    c = load('pi.mat');                  % cartctl export --mat pi.mat controllers/pi.toml
    C = ss(c.motor_a.A, c.motor_a.B, c.motor_a.C, c.motor_a.D, c.Ts);   % inputs [r; y]
    g = load('ground.mat');              % cartctl export --mat ground.mat models/ground.toml
    G = tf(g.motor_a.num, g.motor_a.den, g.Ts);

In Python, python-control objects from the same file::

    import numpy as np, scipy.io, control
    m = scipy.io.loadmat("pi.mat", simplify_cells=True)
    a = m["motor_a"]
    C = control.ss(*(np.atleast_2d(a[k]) for k in "ABCD"), m["Ts"],
                   inputs=["r", "y"], outputs=["u"])
    G = control.tf(a["num"], a["den"], m["Ts"])          # from a model's .mat

(``simplify_cells`` squeezes a 1×n matrix to a vector; ``np.atleast_2d`` gives the row back, which
is the right shape for each of A, B, C, D.)
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cartctl.data.modelfile import ModelFile
from cartctl.design.controller_ss import controller_state_space
from cartctl.design.controllerfile import ControllerFile

__all__ = ["controller_mat", "model_mat", "write_mat"]

_KALMAN_KEYS = ("A", "B", "C", "Q", "R", "P", "L", "timing_noise_std_ticks")


def model_mat(models: ModelFile, source: str = "") -> dict[str, Any]:
    """The ``.mat`` variables of a model file (see the module docstring)."""
    out: dict[str, Any] = {
        "Ts": float(models.period_s),
        "format": "cartctl-model/1",
        "source": source,
    }
    for name, model in models.motors.items():
        std = models.stats.get(name, {}).get("theta_std")
        out[f"motor_{name}"] = {
            "num": np.asarray(model.num(), dtype=float),
            "den": np.asarray(model.den(), dtype=float),
            "theta": np.asarray(model.theta, dtype=float),
            "theta_std": np.asarray(std if std is not None else [], dtype=float),
            "na": model.na,
            "nb": model.nb,
            "nk": model.nk,
            "Ts": float(model.period_s),
        }
    return out


def _estimator(entry: Mapping[str, Any]) -> dict[str, Any]:
    return {k: np.asarray(entry[k], dtype=float) for k in _KALMAN_KEYS if k in entry}


def controller_mat(controller: ControllerFile, source: str = "") -> dict[str, Any]:
    """The ``.mat`` variables of a controller file (see the module docstring).

    Raises
    ------
    KeyError, TypeError, ValueError
        A motor entry lacks a gain or holds something that is not a number (a loaded
        :class:`ControllerFile` has been checked, so only for hand-made objects).
    """
    ts = float(controller.period_s)
    out: dict[str, Any] = {
        "Ts": ts,
        "method": controller.method,
        "loop_delay_ticks": int(controller.loop_delay_ticks or 0),
        "extra_delay_ticks": int(controller.request.get("extra_delay_ticks", 0)),
        "voltage_limit_v": float(controller.voltage_limit_v),
        "format": "cartctl-controller/1",
        "source": source,
    }
    for name, entry in controller.motors.items():
        ss = controller_state_space(controller.method, entry, ts)
        num, den = ss.feedback_tf()
        motor: dict[str, Any] = {
            "A": ss.A,
            "B": ss.B,
            "C": ss.C,
            "D": ss.D,
            "states": np.array(ss.states, dtype=object),
            "inputs": np.array(["reference_rad_s", "speed_rad_s"], dtype=object),
            "outputs": np.array(["voltage_v"], dtype=object),
            "feedback_num": num,
            "feedback_den": den,
            "Ts": ts,
        }
        if controller.method == "pi":
            motor.update(kp=float(entry["kp"]), ki=float(entry["ki"]))
            motor["anti_windup"] = str(entry.get("anti_windup", "conditional"))
        else:
            motor.update(
                K=np.asarray(entry["K"], dtype=float), Ki=float(entry["Ki"]), Kr=float(entry["Kr"])
            )
        if entry.get("estimator") is not None:
            motor["estimator"] = _estimator(entry["estimator"])
            motor["L"] = np.asarray(entry["estimator"]["L"], dtype=float)
        out[f"motor_{name}"] = motor
    return out


def write_mat(variables: Mapping[str, Any], path: str | Path) -> Path:
    """Write ``variables`` as a MATLAB 5 ``.mat`` file (creating folders); returns the path."""
    import scipy.io

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    scipy.io.savemat(path, dict(variables), oned_as="row", do_compression=True)
    return path
