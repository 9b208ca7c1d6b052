"""``cartctl.measures.numfmt``: one rounding per column, on hand-computed cases."""

from __future__ import annotations

import math

import pytest

from cartctl.measures.numfmt import column_decimals, exact_decimals, format_column, format_fixed


@pytest.mark.parametrize(
    ("values", "kwargs", "expected"),
    [
        ([0.791, 1.78e-15], {}, ["0.791", "0.000"]),  # a numerical zero beside the scale
        ([18.2, 1.75, 0.0], {}, ["18.2", "1.8", "0.0"]),  # 3 figures of the largest
        ([9.996, 1.0], {}, ["10.0", "1.0"]),  # rounding carries into a new digit
        ([1234.5, 56.0], {}, ["1230", "60"]),  # beyond three digits: to tens
        ([0.0, 0.0], {}, ["0", "0"]),
        ([None, math.nan, math.inf, 2.0], {}, ["—", "—", "∞", "2.00"]),
        ([-0.0004, 0.5], {}, ["0.000", "0.500"]),  # no '-0.000'
        ([0.0435, 0.0693], {"factor": 1e3}, ["43.5", "69.3"]),  # s printed in ms
        ([0.002], {"scale": 0.5}, ["0.002"]),  # decimals from the scale: 0.500 → 3
    ],
)
def test_format_column(values: list, kwargs: dict, expected: list[str]) -> None:
    assert format_column(values, **kwargs) == expected


def test_decimals_and_fixed_format() -> None:
    assert column_decimals([0.00123]) == 5
    assert column_decimals([123.0]) == 0
    assert column_decimals([5e-15]) == 6  # capped: no 17 decimals
    assert format_fixed(-0.004, 3) == "-0.004"
    assert exact_decimals([0.04, 0.1, 0.16]) == 2
    assert exact_decimals([65.0, 70.0]) == 0
