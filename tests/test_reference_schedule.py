"""References computed chunk by chunk: the same values as all at once, one chunk in memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.errors import InputError
from cartctl.reference import ReferenceSchedule, reference_signal

DAY_TICKS = 24 * 3600 * 100


@given(
    spec=st.sampled_from(["step:8", "step:-3:0.37", "square:5:0.23", "ramp:4:6", "const:2.5"]),
    n=st.integers(1, 3000),
    chunk=st.integers(1, 700),
)
@settings(max_examples=60, deadline=None, derandomize=True)
def test_chunks_give_the_values_of_the_whole(spec: str, n: int, chunk: int) -> None:
    whole = reference_signal(spec, n, 0.01, "a")
    schedule = ReferenceSchedule(spec, n, 0.01, "a", chunk_ticks=chunk)
    assert len(schedule) == n
    np.testing.assert_array_equal([schedule[k] for k in range(n)], whole)
    np.testing.assert_array_equal(np.concatenate(list(schedule.chunks())), whole)
    assert schedule.peak_abs() == float(np.max(np.abs(whole)))


def test_a_file_reference_is_read_once_and_interpolated_per_chunk(tmp_path: Path) -> None:
    path = tmp_path / "ref.csv"
    path.write_text("time_s,reference_a,reference_b\n0,0,0\n1,10,-10\n2,10,-10\n", "utf-8")
    for motor in "ab":
        schedule = ReferenceSchedule(f"file:{path}", 300, 0.01, motor, chunk_ticks=37)
        whole = reference_signal(f"file:{path}", 300, 0.01, motor)
        np.testing.assert_array_equal([schedule[k] for k in range(300)], whole)
    assert schedule[150] == -10.0 and schedule[50] == pytest.approx(-5.0)


def test_a_day_long_reference_holds_one_chunk() -> None:
    """24 h of ticks: one minute of values held at a time, any tick reachable."""
    schedule = ReferenceSchedule("square:8:2", DAY_TICKS, 0.01, "a")
    assert len(schedule._values) == 6000  # one chunk, not 8.64 million values
    assert schedule[DAY_TICKS - 1] == -8.0  # t = 86399.99 s: the second half of a 2 s period
    assert schedule[0] == 8.0 and len(schedule._values) == 6000
    with pytest.raises(IndexError):
        schedule[DAY_TICKS]


def test_a_bad_spec_fails_when_the_schedule_is_made() -> None:
    with pytest.raises(InputError, match="unknown reference"):
        ReferenceSchedule("sine:3", 100)
