"""One damping rule for ``inspect`` and ``design``: ζ and f_n of a discrete pole as python-control's
``control.damp`` gives them (s = ln z / Ts), and the two commands agree on the same pole.

Expectations come from ``control.damp`` on a system with exactly the pole in question; where it
gives NaN (ζ at z = 0 and z = 1) or ∞ (ωn at z = 0), cartctl gives None (null in JSON).
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import control
import numpy as np
import pytest

from cartctl.cli import main
from cartctl.model import pole_damping

TS = 0.01
POLES = [0.0, -0.5, 0.6 + 0.3j, 0.5, 1.0, -1.0, 1.2, math.exp(-0.5)]


def _damp(z: complex) -> tuple[float, float]:
    """(ζ, ωn in rad/s) of ``z`` by ``control.damp`` on a system with that pole (and its
    conjugate when complex)."""
    den = np.real(np.poly([z, np.conj(z)])) if z.imag else [1.0, -z.real]
    with warnings.catch_warnings():  # log(0) and 0/0 at z = 0 and z = 1
        warnings.simplefilter("ignore", RuntimeWarning)
        wn, zeta, poles = control.damp(control.tf([1.0], den, TS), doprint=False)
    j = int(np.argmin(np.abs(poles - z)))
    return float(zeta[j]), float(wn[j])


@pytest.mark.parametrize("z", POLES)
def test_pole_damping_is_control_damp(z: complex) -> None:
    zeta, wn = _damp(complex(z))
    damping, freq_hz = pole_damping(z, TS)
    if math.isnan(zeta):
        assert damping is None
    else:
        assert damping == pytest.approx(zeta, abs=1e-12)
    if math.isinf(wn):
        assert freq_hz is None
    else:
        assert freq_hz == pytest.approx(wn / (2.0 * math.pi), rel=1e-12, abs=1e-12)


def test_the_cases_by_hand() -> None:
    assert pole_damping(0.0, TS) == (None, None)  # a pure delay: ln z = −∞
    assert pole_damping(1.0, TS) == (None, 0.0)  # an integrator: s = 0
    # negative real: s = (ln 0.5 + jπ)/Ts, so f_n = |s|/2π, not the Nyquist 50 Hz
    damping, freq_hz = pole_damping(-0.5, TS)
    s_abs = math.hypot(math.log(0.5), math.pi)
    assert freq_hz == pytest.approx(s_abs / (2 * math.pi * TS)) and freq_hz > 50.0
    assert damping == pytest.approx(-math.log(0.5) / s_abs)
    # a positive real pole inside the unit circle: ζ = 1; outside: ζ = −1
    assert pole_damping(0.5, TS)[0] == pytest.approx(1.0)
    assert pole_damping(1.5, TS)[0] == pytest.approx(-1.0)
    # a complex pair from a continuous one (ζ = 0.3, ωn = 30 rad/s)
    s = complex(-0.3 * 30.0, 30.0 * math.sqrt(1 - 0.3**2))
    damping, freq_hz = pole_damping(np.exp(s * TS), TS)
    assert damping == pytest.approx(0.3) and freq_hz == pytest.approx(30.0 / (2 * math.pi))


def test_inspect_and_design_report_the_same_damping_for_the_same_pole(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    poles = [0.0, -0.5, 0.6 + 0.3j, 0.6 - 0.3j]
    # a model with these poles: A(z) = (z + 0.5)(z² − 1.2 z + 0.45), nk = 4 (one tick beyond na) adds the one at 0
    ar = np.real(np.poly(poles[1:]))[1:]
    model = tmp_path / "m.toml"
    model.write_text(
        'format = "cartctl-model/1"\nperiod_s = 0.01\n\n[motors.a]\n'
        f"theta = [{', '.join(repr(float(v)) for v in ar)}, 1.0]\nna = 3\nnb = 1\nnk = 4\n",
        encoding="utf-8",
    )
    assert main(["inspect", str(model), "--json"]) == 0
    inspected = json.loads(capsys.readouterr().out)["motors"]["a"]["poles"]
    ground = Path(__file__).resolve().parents[1] / "models" / "ground.toml"
    placed = ",".join(str(p).strip("()") for p in poles)
    argv = ["design", str(ground), "--method", "poles", "--poles", placed, "--bias-drift-v", "0"]
    assert main([*argv, "--json"]) == 0
    table = json.loads(capsys.readouterr().out)["motors"]["a"]["closed_loop_pole_table"]
    assert len(inspected) == len(table) == len(poles)
    for row in table:
        z = complex(row["re"], row["im"])
        (same,) = [p for p in inspected if abs(complex(p["re"], p["im"]) - z) < 1e-9]
        for key in ("damping", "freq_hz"):
            if row[key] is None:
                assert same[key] is None, (z, key)
            else:
                assert same[key] == pytest.approx(row[key], rel=1e-9), (z, key)
    assert [r["damping"] for r in table if r["re"] == r["im"] == 0.0] == [None]
