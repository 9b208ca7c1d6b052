"""The microOS dialect: CRC_EXTRA from the XML, the encoder against the protocol's test vectors."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cartctl.link.dialect import (
    CRC_EXTRA,
    GPIOX_CRC_EXTRA,
    PAYLOAD_LENGTH,
    Encoder,
    encode_gpiox_v2,
)

# docs/serial-protocol.md §5 (MAVLink 1, sysid 0, compid 0, seq 0)
EVENT_1000 = bytes.fromhex("fe 02 00 00 00 04 e8 03 a1 33")
HEARTBEAT_1234 = bytes.fromhex("fe 0e 00 00 00 00 d2 04 00 00 14 00 00 00 00 00 00 00 00 02 77 95")
GPIO_PC_TO_CART = (
    bytes.fromhex("fe 34 00 00 00 03 00 00 00 00 00 00 c0 40 00 00 c0 c0")
    + bytes(24)
    + bytes.fromhex("07 00 00 00 01 00 00 00")
    + bytes(8)
    + bytes.fromhex("57 46")
)
GPIO_CART_TO_PC_ARGS = (17170, [11.92, -11.57, 5.976, -5.976, 1.5, -1.5, 0.0, 0.0], [7, 42, 1, 0])
PRINT_ROBOT_ENABLED = (
    bytes.fromhex("fe 20 00 00 00 05 52 6f 62 6f 74 20 65 6e 61 62 6c 65 64 2e")
    + bytes(18)
    + bytes.fromhex("21 cd")
)


def test_crc_extra_and_lengths_match_the_protocol() -> None:
    assert CRC_EXTRA == {0: 31, 1: 215, 3: 172, 4: 133, 5: 107}
    assert PAYLOAD_LENGTH == {0: 14, 1: 22, 3: 52, 4: 2, 5: 32}


def test_crc_extra_of_gpiox() -> None:
    assert GPIOX_CRC_EXTRA == 221


def test_importing_the_link_generates_nothing_and_prints_nothing() -> None:
    code = "import sys, cartctl.link; print(sorted(m for m in sys.modules if 'pymavlink' in m))"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert result.stdout == "[]\n"  # the shipped module is imported, pymavlink's generator is not
    assert result.stderr == ""


def test_encoder_reproduces_the_test_vectors() -> None:
    assert Encoder().event(1000) == EVENT_1000
    assert Encoder().heartbeat(1234) == HEARTBEAT_1234
    assert Encoder().gpio(0, [6.0, -6.0, 0, 0, 0, 0, 0, 0], [7, 1, 0, 0]) == GPIO_PC_TO_CART
    cart = Encoder().gpio(*GPIO_CART_TO_PC_ARGS)
    assert len(cart) == 60
    assert cart[-2:] == bytes.fromhex("9d ea")
    assert Encoder().print_text("Robot enabled.") == [PRINT_ROBOT_ENABLED]


def test_encoder_sequence_number_counts_and_wraps() -> None:
    encoder = Encoder(sysid=3, compid=7)
    encoder.seq = 254
    frames = [encoder.event(1000), *encoder.print_text("x" * 40), encoder.heartbeat(0)]
    assert [f[2] for f in frames] == [254, 255, 0, 1]
    assert all(f[3:5] == bytes([3, 7]) for f in frames)
    assert encoder.seq == 2


def test_print_text_splits_into_32_byte_frames_on_character_bounds() -> None:
    encoder = Encoder()
    assert encoder.print_text("") == []
    assert len(encoder.print_text("a" * 32)) == 1
    assert len(encoder.print_text("a" * 33)) == 2
    frames = encoder.print_text("a" + "é" * 20)
    chunks = [frame[6:38].rstrip(b"\x00") for frame in frames]
    assert [len(c) for c in chunks] == [31, 10]
    assert "".join(c.decode("utf-8") for c in chunks) == "a" + "é" * 20
    with pytest.raises(ValueError, match="NUL"):
        encoder.print_text("a\x00b")


@pytest.mark.parametrize(
    ("floats", "ints", "message"),
    [
        ([0.0] * 7, [0] * 4, "8 floats and 4 ints"),
        ([0.0] * 8, [0] * 5, "8 floats and 4 ints"),
        ([0.0] * 8, [2**31, 0, 0, 0], "does not fit"),
        ([1e39] + [0.0] * 7, [0] * 4, "does not fit"),
    ],
)
def test_gpio_rejects_bad_channels(floats: list[float], ints: list[int], message: str) -> None:
    encoder = Encoder()
    with pytest.raises(ValueError, match=message):
        encoder.gpio(0, floats, ints)
    assert encoder.seq == 0


def test_encoder_rejects_out_of_range_fields() -> None:
    encoder = Encoder()
    with pytest.raises(ValueError, match="time_ms"):
        encoder.gpio(-1, [0.0] * 8, [0] * 4)
    with pytest.raises(ValueError, match="EVENT type"):
        encoder.event(70000)
    with pytest.raises(ValueError, match="8 bytes"):
        encoder.heartbeat(0, data=bytes(7))


def test_gpiox_v2_frame_layout() -> None:
    frame = encode_gpiox_v2(1, [0.0] * 12, seq=5, sysid=2, compid=9)
    # payload truncated to the one non-zero byte of the time
    assert frame[:10] == bytes([0xFD, 1, 0, 0, 5, 2, 9, 14, 0, 0])
    assert frame[10] == 1
    assert len(frame) == 13
    assert len(encode_gpiox_v2(0, [0.0] * 12)) == 13  # at least one payload byte
    assert len(encode_gpiox_v2(0, [0.0] * 11 + [1.0])) == 64
    with pytest.raises(ValueError, match="12 floats"):
        encode_gpiox_v2(0, [0.0] * 8)
