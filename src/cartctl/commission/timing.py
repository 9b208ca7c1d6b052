"""Commissioning's actuation-timing plants: the identified model with its command landing later.

``cartctl tune --robust`` covers the actuation timing with the physics preset (the course's cart)
run at 3 and 10 ms. Commissioning tunes for the *user's* cart, so its timing plants are made from
the identified model itself:

- whole ticks: the sampled plants of :mod:`cartctl.tune.uncertainty` already shift the loop delay
  by −1, 0 or +1 tick;
- within a tick: :func:`later_command` lands every command a fraction f of a tick later than on
  the day the model was identified (:data:`LATER_FRACTIONS`: 2 and 4 ms at 10 ms). The bridge
  applies the newest command at the cart's next ``io()``, so on one cart where a command lands
  within the tick is fixed by its firmware; what moves it is when the host's reply gets through,
  and the Mega's USB chip passes a reply on at its 4.096 ms timer at the latest. A reply later
  than that misses its tick: a whole tick, which the sampled plants cover.

A command landing f·Ts late means that over each tick the motor sees the previous command for a
fraction f and the new one for 1 − f. To first order in the tick (the motor's dynamics slow
against Ts, which the cart's ~50 ms mechanical time constant is), the tick's averaged speed then
answers the blend (1 − f)·u(k) + f·u(k − 1): the numerator B(z) becomes B(z)·((1 − f) + f z⁻¹),
one term longer. It keeps the DC gain and the poles, adds the phase lag of f ticks at low
frequency, and is an ARX model the tuning's simulated loop runs as it is.
"""

from __future__ import annotations

import numpy as np

from cartctl.errors import InputError
from cartctl.model import ArxModel

LATER_FRACTIONS = (0.2, 0.4)
"""Fractions of a tick (2 and 4 ms at 10 ms) by which the commands land later in the timing plants."""


def later_command(model: ArxModel, fraction: float) -> ArxModel:
    """``model`` with every command landing ``fraction`` of a tick later (see the module docstring).

    Parameters
    ----------
    model : ArxModel
    fraction : float
        f in [0, 1] (ticks).

    Returns
    -------
    ArxModel
        Same poles, input delay and DC gain; nb + 1 numerator coefficients
        (1 − f)·[b, 0] + f·[0, b].
    """
    f = float(fraction)
    if not 0.0 <= f <= 1.0:
        raise InputError(f"a command can land 0 to 1 tick later here, got {fraction}")
    b = np.asarray(model.b, dtype=float)
    blended = (1.0 - f) * np.append(b, 0.0) + f * np.insert(b, 0, 0.0)
    return ArxModel(tuple(model.ar), tuple(blended), model.nk, model.period_s)
