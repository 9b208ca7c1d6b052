"""Models and controllers as MATLAB 5 ``.mat`` files (``cartctl export --mat``): the variables
(docs/design.md) as plain dicts of numpy arrays, and :func:`write_mat`."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cartctl.data.modelfile import ModelFile
from cartctl.data.outputs import writing
from cartctl.data.tomlfile import CONTROLLER_FORMAT, MODEL_FORMAT
from cartctl.design.controller_ss import controller_state_space, feedback_gains
from cartctl.design.controllerfile import ControllerFile, build_controllers
from cartctl.errors import DataFileError

_KALMAN_KEYS = ("A", "B", "C", "Q", "R", "P", "L", "timing_noise_std_ticks")


def model_mat(models: ModelFile, source: str = "") -> dict[str, Any]:
    """The ``.mat`` variables of a model file."""
    out: dict[str, Any] = {
        "Ts": float(models.period_s),
        "format": MODEL_FORMAT,
        "source": source,
    }
    for name, model in models.motors.items():
        std = models.stats.get(name, {}).get("theta_std")
        try:
            std = np.asarray(std if std is not None else [], dtype=float)
        except (TypeError, ValueError):
            problem = f"theta_std in [motors.{name}] must be a list of numbers, got {std!r}"
            raise DataFileError(models.path or "model file", problem) from None
        out[f"motor_{name}"] = {
            "num": np.asarray(model.num(), dtype=float),
            "den": np.asarray(model.den(), dtype=float),
            "theta": np.asarray(model.theta, dtype=float),
            "theta_std": std,
            "na": model.na,
            "nb": model.nb,
            "nk": model.nk,
            "Ts": float(model.period_s),
        }
    return out


def controller_mat(controller: ControllerFile, source: str = "") -> dict[str, Any]:
    """The ``.mat`` variables of a loaded controller file, after the checks the loop applies (keys,
    gains, anti-windup, estimator: one line naming the file and the entry)."""
    build_controllers(controller)
    ts = float(controller.period_s)
    out: dict[str, Any] = {
        "Ts": ts,
        "method": controller.method,
        "loop_delay_ticks": int(controller.loop_delay_ticks or 0),
        "extra_delay_ticks": int(controller.request.get("extra_delay_ticks", 0)),
        "voltage_limit_v": float(controller.voltage_limit_v),
        "format": CONTROLLER_FORMAT,
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
            windup = str(entry.get("anti_windup", "conditional"))
            motor.update(kp=float(entry["kp"]), ki=float(entry["ki"]), anti_windup=windup)
        else:
            gains = feedback_gains(entry, ts)
            motor.update(K=gains.K, Ki=gains.Ki, Kr=gains.Kr)
        if (estimator := entry.get("estimator")) is not None:
            motor["estimator"] = {
                k: np.asarray(estimator[k], float) for k in _KALMAN_KEYS if k in estimator
            }
            motor["L"] = np.asarray(estimator["L"], dtype=float)
        out[f"motor_{name}"] = motor
    return out


def write_mat(variables: Mapping[str, Any], path: str | Path) -> Path:
    """Write ``variables`` as a MATLAB 5 ``.mat`` file (creating folders); returns the path."""
    import scipy.io

    path = Path(path)
    with writing(path):
        scipy.io.savemat(path, dict(variables), oned_as="row", do_compression=True)
    return path
