"""``cartctl commission``: from a connected cart to a verified controller, in five stages.

1. checks: port, heartbeat and loop delay; each motor's direction, encoder sign and breakaway
   voltage; the excitation amplitude they allow;
2. the report's square excitation at that amplitude;
3. identification with a validation split, and its verdict;
4. tuning: ``tune --robust``'s machinery over the model's uncertainty and actuation timing;
5. verification: a closed-loop step on the cart against the tuning's prediction.

:mod:`.stages` drives the plant and writes files (:mod:`.report`); :mod:`.checks` holds the
judgements and :mod:`.tuning` the tuning, numbers in, numbers out.
"""

from __future__ import annotations

from cartctl.errors import CartctlError


class StageError(CartctlError, RuntimeError):
    """A stage found the cart or its model unfit: exit code 1, one line saying which stage, what was
    measured and what to do."""

    exit_code = 1
