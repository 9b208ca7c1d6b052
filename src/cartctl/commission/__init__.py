"""``cartctl commission`` (docs/commission.md): :mod:`.stages` drives the plant and writes files
(:mod:`.report`); :mod:`.checks` and :mod:`.tuning` judge and tune, numbers in, numbers out."""

from cartctl.errors import CartctlError


class StageError(CartctlError, RuntimeError):
    """A stage found the cart or its model unfit: exit code 1, one line (which stage, what was
    measured, what to do)."""

    exit_code = 1
