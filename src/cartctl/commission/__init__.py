"""``cartctl commission``: from a connected cart to a verified controller, in stages.

The stages, each a small module, run in this order by :mod:`cartctl.cli.commands.commission`:

1. :mod:`.checks`: the port, the heartbeat and the loop delay; each motor's direction and encoder
   sign from a short pulse; each motor's breakaway voltage from a slow ramp; the excitation
   amplitude they allow (:func:`.checks.choose_amplitude`).
2. the report's square excitation at that amplitude (:func:`cartctl.signals.make_signal`).
3. :mod:`.modelcheck`: identification with a validation split and its verdict.
4. :mod:`.tuning`: ``tune --robust``'s machinery over θ's uncertainty and the actuation timing of
   the identified model (:mod:`.timing`), and the chosen controller.
5. :mod:`.verify`: a closed-loop step on the cart against the tuning's prediction.

Numbers in, numbers out, wherever a stage can be: the plant is driven only by
:mod:`cartctl.cli.commands.commission` and the functions named ``run_*``.
"""

from __future__ import annotations

from cartctl.errors import CartctlError


class StageError(CartctlError, RuntimeError):
    """A stage of commissioning found the cart or its model unfit: exit code 1, one line.

    The message says which stage, what was measured, and what to do.
    """

    exit_code = 1
