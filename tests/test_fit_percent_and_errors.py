"""Edge inputs of two core helpers: the NRMSE fit of arrays of any shape, and an error message
that is already one printable line (returned as it is, not rebuilt)."""

from __future__ import annotations

import numpy as np
import pytest

from cartctl.errors import InputError
from cartctl.measures.metrics import fit_percent


@pytest.mark.parametrize(
    ("measured", "modelled"),
    [
        (np.arange(6.0).reshape(3, 2), np.arange(6.0).reshape(3, 2) + 0.1),  # 2-D
        (np.arange(6.0).reshape(6, 1), np.arange(6.0).reshape(6, 1) + 0.1),  # a column
    ],
)
def test_fit_percent_takes_arrays_of_any_shape(measured: np.ndarray, modelled: np.ndarray) -> None:
    flat = fit_percent(measured.ravel(), modelled.ravel())
    assert fit_percent(measured, modelled) == pytest.approx(flat, rel=1e-12)
    assert fit_percent(measured.tolist(), modelled.tolist()) == pytest.approx(flat, rel=1e-12)


def test_fit_percent_of_a_scalar_is_nan_as_for_any_constant() -> None:
    assert np.isnan(fit_percent(3.0, 2.0))


def test_a_printable_error_message_is_not_rebuilt_character_by_character() -> None:
    # one_line's fast path, kept in CartctlError.__str__: a 2 MB message took 0.1 s without it
    # (2 ms with it); control characters still show as escapes
    message = "column 'x' " + "y" * 2_000_000
    assert str(InputError(message)) is message
    assert str(InputError("a\nb\tc")) == "a\\nb\\tc"
