"""The bridge channel map, both directions, also through real frames."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cartctl.link.bridge import SEQ_MODULO, CartSample, HostCommand, next_seq, tick_difference
from cartctl.link.dialect import Encoder, Framer, Gpio

f32 = st.floats(width=32, allow_nan=False)
seqs = st.integers(0, SEQ_MODULO - 1)


@settings(max_examples=50, deadline=None)
@given(f32, f32, seqs, st.booleans())
def test_host_command_round_trip_through_a_frame(a: float, b: float, seq: int, drive: bool) -> None:
    command = HostCommand(a, b, seq, drive)
    floats, ints = command.to_channels()
    assert len(floats) == 8
    assert len(ints) == 4
    assert HostCommand.from_channels(floats, ints) == command
    (gpio,) = Framer().feed(Encoder().gpio(0, floats, ints))
    assert isinstance(gpio, Gpio)
    assert HostCommand.from_channels(gpio.floats, gpio.ints) == command


def test_host_command_channel_layout() -> None:
    floats, ints = HostCommand(6.0, -6.0, 7, True).to_channels()
    assert floats == (6.0, -6.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert ints == (7, 1, 0, 0)
    assert HostCommand(0.0, 0.0, 7, False).to_channels()[1] == (7, 0, 0, 0)
    assert not HostCommand.from_channels(floats, (7, 2, 0, 0)).drive
    with pytest.raises(ValueError, match="8 floats and 4 ints"):
        HostCommand.from_channels(floats[:2], ints)


@settings(max_examples=50, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.lists(f32, min_size=6, max_size=6),
    seqs,
    seqs,
    st.booleans(),
    st.booleans(),
)
def test_cart_sample_round_trip_through_a_frame(
    time_ms: int, values: list[float], echo: int, tick: int, driving: bool, tripped: bool
) -> None:
    sample = CartSample(time_ms, *values, echo, tick, driving, tripped)
    floats, ints = sample.to_channels()
    assert CartSample.from_gpio(Gpio(time_ms, floats, ints)) == sample
    (gpio,) = Framer().feed(Encoder().gpio(time_ms, floats, ints))
    assert isinstance(gpio, Gpio)
    assert CartSample.from_gpio(gpio) == sample


@pytest.mark.parametrize(
    ("status", "driving", "tripped"),
    [(0, False, False), (1, True, False), (2, False, True), (3, True, True)],
)
def test_status_bits(status: int, driving: bool, tripped: bool) -> None:
    sample = CartSample.from_gpio(Gpio(0, (0.0,) * 8, (0, 0, status, 0)))
    assert (sample.driving, sample.watchdog_tripped) == (driving, tripped)
    assert sample.status == status
    assert sample.to_channels()[1][2] == status


def test_cart_sample_channel_layout() -> None:
    sample = CartSample(17170, 11.92, -11.57, 5.976, -5.976, 1.5, -1.5, 7, 42, True, False)
    floats, ints = sample.to_channels()
    assert floats == (11.92, -11.57, 5.976, -5.976, 1.5, -1.5, 0.0, 0.0)
    assert ints == (7, 42, 1, 0)
    assert Encoder().gpio(sample.time_ms, floats, ints)[-2:] == bytes.fromhex("9d ea")


@pytest.mark.parametrize(
    ("channel", "version"),
    [(0.0, 0), (2.0, 2), (float("nan"), 0), (-1.0, 0), (2.5, 0), (1e9, 0), (float("inf"), 0)],
)
def test_bridge_version_from_float_channel_6(channel: float, version: int) -> None:
    """A bridge before version 2 sends 0 in float 6; anything not a small whole number is 0."""
    floats = (0.0,) * 6 + (channel, 0.0)
    assert CartSample.from_gpio(Gpio(0, floats, (0, 0, 0, 0))).bridge_version == version


def test_sequence_wraps() -> None:
    assert next_seq(0) == 1
    assert next_seq(SEQ_MODULO - 1) == 0
    assert tick_difference(SEQ_MODULO - 2, 1) == 3
    assert tick_difference(5, 5) == 0
    assert tick_difference(6, 5) == SEQ_MODULO - 1
