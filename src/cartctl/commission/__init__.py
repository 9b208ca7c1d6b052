"""``cartctl commission``: from a connected cart to a verified controller in five stages (checks,
excitation, identification, tuning, verification; docs/commission.md). :mod:`.stages` drives the
plant and writes files (:mod:`.report`); :mod:`.checks` holds the judgements and :mod:`.tuning`
the tuning, numbers in, numbers out."""

from __future__ import annotations

from cartctl.errors import CartctlError


class StageError(CartctlError, RuntimeError):
    """A stage found the cart or its model unfit: exit code 1, one line saying which stage, what was
    measured and what to do."""

    exit_code = 1
