"""``cartctl commission``: from a connected cart to a verified controller, in five stages.

1. :mod:`.checks`: port, heartbeat and loop delay; each motor's direction, encoder sign and
   breakaway voltage; the excitation amplitude they allow.
2. the report's square excitation at that amplitude.
3. :mod:`.modelcheck`: identification with a validation split, and its verdict.
4. :mod:`.tuning`: ``tune --robust``'s machinery over the model's uncertainty and actuation
   timing, and the chosen controller.
5. :mod:`.verify`: a closed-loop step on the cart against the tuning's prediction.

Only :mod:`.stages` drives the plant or writes files; the rest is numbers in, numbers out."""

from __future__ import annotations

from cartctl.errors import CartctlError


class StageError(CartctlError, RuntimeError):
    """A stage found the cart or its model unfit: exit code 1, one line saying which stage, what was
    measured and what to do."""

    exit_code = 1
