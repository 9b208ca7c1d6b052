"""The stream framer: test vectors, round trips, resynchronisation, statistics."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.generator.mavcrc import x25crc

from cartctl.link.dialect import (
    Encoder,
    Event,
    Framer,
    GenerationBFrame,
    Gpio,
    Heartbeat,
    Message,
    PrintText,
    ThreadInfo,
    encode_gpiox_v2,
)
from test_link_dialect import (
    EVENT_1000,
    GPIO_CART_TO_PC_ARGS,
    GPIO_PC_TO_CART,
    HEARTBEAT_1234,
    PRINT_ROBOT_ENABLED,
)

# --- strategies: (encoder call, expected message without header fields) ----------------------

f32 = st.floats(width=32, allow_nan=False)
i32 = st.integers(-(2**31), 2**31 - 1)
u32 = st.integers(0, 2**32 - 1)

gpio_args = st.tuples(
    u32, st.lists(f32, min_size=8, max_size=8), st.lists(i32, min_size=4, max_size=4)
)
heartbeat_args = st.tuples(u32, st.integers(0, 255), st.binary(min_size=8, max_size=8))
print_args = st.text(st.characters(min_codepoint=1, max_codepoint=127), min_size=1, max_size=32)


@st.composite
def frame_specs(draw: st.DrawFn) -> tuple[str, tuple]:
    """One message to encode: a kind and its arguments."""
    kind = draw(st.sampled_from(["gpio", "heartbeat", "event", "print", "gpiox"]))
    if kind == "gpio":
        return kind, draw(gpio_args)
    if kind == "heartbeat":
        return kind, draw(heartbeat_args)
    if kind == "event":
        return kind, (draw(st.integers(0, 0xFFFF)),)
    if kind == "print":
        return kind, (draw(print_args),)
    return kind, (draw(u32), draw(st.lists(f32, min_size=12, max_size=12)))


def encode(specs: list[tuple[str, tuple]]) -> tuple[list[bytes], list[Message]]:
    """Frames for the specs from one encoder, and the messages they must decode to."""
    encoder = Encoder()
    frames: list[bytes] = []
    expected: list[Message] = []
    for kind, args in specs:
        seq = encoder.seq
        if kind == "gpio":
            t, floats, ints = args
            frames.append(encoder.gpio(t, floats, ints))
            expected.append(Gpio(t, tuple(floats), tuple(ints), seq))
        elif kind == "heartbeat":
            t, vehicle, data = args
            frames.append(encoder.heartbeat(t, vehicle, data))
            expected.append(Heartbeat(t, vehicle, data, 2, seq))
        elif kind == "event":
            frames.append(encoder.event(args[0]))
            expected.append(Event(args[0], seq))
        elif kind == "print":
            (frame,) = encoder.print_text(args[0])
            frames.append(frame)
            expected.append(PrintText(args[0], seq))
        else:
            gen_b_seq = len(frames) % 256
            frames.append(encode_gpiox_v2(*args, seq=gen_b_seq, sysid=1, compid=2))
            expected.append(GenerationBFrame(14, gen_b_seq, 1, 2))
    return frames, expected


def thread_info_frame(payload: bytes, seq: int = 0) -> bytes:
    """A THREAD_INFO frame built by hand (id 1, CRC_EXTRA 215)."""
    body = bytes([len(payload), seq, 0, 0, 1]) + payload
    crc = x25crc(body + bytes([215])).crc
    return b"\xfe" + body + crc.to_bytes(2, "little")


# --- test vectors --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("frame", "expected"),
    [
        (EVENT_1000, Event(1000)),
        (HEARTBEAT_1234, Heartbeat(1234, 20, bytes(8), 2)),
        (GPIO_PC_TO_CART, Gpio(0, (6.0, -6.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (7, 1, 0, 0))),
        (PRINT_ROBOT_ENABLED, PrintText("Robot enabled.")),
    ],
)
def test_framer_decodes_the_test_vectors(frame: bytes, expected: Message) -> None:
    framer = Framer()
    assert framer.feed(frame) == [expected]
    assert framer.stats.to_dict() == {
        "frames": 1,
        "crc_errors": 0,
        "garbage_bytes": 0,
        "seq_gaps": 0,
        "lost_frames": 0,
        "generation_b_frames": 0,
    }
    assert framer.pending == 0


def test_framer_decodes_the_cart_gpio_vector() -> None:
    time_ms, floats, ints = GPIO_CART_TO_PC_ARGS
    frame = Encoder().gpio(time_ms, floats, ints)
    (gpio,) = Framer().feed(frame)
    assert isinstance(gpio, Gpio)
    assert gpio.time_ms == time_ms
    assert gpio.ints == tuple(ints)
    assert gpio.floats == pytest.approx(floats, rel=1e-6)


def test_event_button() -> None:
    assert Event(1000).button == 0
    assert Event(1007).button == 7
    assert Event(1008).button is None
    assert Event(999).button is None


# --- round trips and chunking ----------------------------------------------------------------


@settings(max_examples=150, deadline=None)
@given(frame_specs())
def test_encode_decode_round_trip(spec: tuple[str, tuple]) -> None:
    frames, expected = encode([spec])
    framer = Framer()
    assert framer.feed(frames[0]) == expected
    assert framer.stats.frames == 1
    assert framer.stats.garbage_bytes == 0


@settings(max_examples=25, deadline=None)
@given(st.lists(frame_specs(), min_size=1, max_size=5))
def test_any_split_of_the_stream_gives_the_same_messages(specs: list[tuple[str, tuple]]) -> None:
    frames, expected = encode(specs)
    stream = b"".join(frames)
    assert Framer().feed(stream) == expected
    for cut in range(len(stream) + 1):
        framer = Framer()
        assert framer.feed(stream[:cut]) + framer.feed(stream[cut:]) == expected
        assert framer.pending == 0
    framer = Framer()
    assert [m for i in range(len(stream)) for m in framer.feed(stream[i : i + 1])] == expected
    assert framer.stats.garbage_bytes == 0
    assert framer.stats.seq_gaps == 0


noise_byte = st.one_of(
    st.sampled_from([0xFE, 0xFD, 0x02, 0x0E, 0x20, 0x34, 0x03, 0x00]), st.integers(0, 255)
)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.lists(noise_byte, max_size=20).map(bytes), frame_specs()),
        min_size=1,
        max_size=5,
    ),
)
def test_garbage_between_frames_is_skipped_and_counted(
    items: list[tuple[bytes, tuple[str, tuple]]],
) -> None:
    # A tail of two GPIO frames (120 bytes) outlasts the longest wait a false start can cause.
    specs = [spec for _, spec in items] + [("gpio", (0, [0.0] * 8, [0] * 4))] * 2
    frames, expected = encode(specs)
    garbage = [noise for noise, _ in items] + [b"", b""]
    stream = b"".join(noise + frame for noise, frame in zip(garbage, frames, strict=True))
    framer = Framer()
    assert framer.feed(stream) == expected
    assert framer.stats.garbage_bytes == sum(len(g) for g in garbage)
    assert framer.stats.frames == len(frames)
    assert framer.stats.seq_gaps == 0
    assert framer.pending == 0


def test_false_start_waits_then_the_real_frame_is_recovered() -> None:
    event = Encoder().event(1000)
    false_start = bytes([0xFE, 52, 0, 0, 0, 3])  # looks like a GPIO header
    framer = Framer()
    assert framer.feed(false_start + event) == []  # waits for 60 bytes
    assert framer.pending == len(false_start) + len(event)
    tail = Encoder().gpio(0, [1.0] * 8, [1] * 4)
    messages = framer.feed(tail)
    assert [type(m) for m in messages] == [Event, Gpio]
    assert framer.stats.crc_errors == 1
    assert framer.stats.garbage_bytes == len(false_start)


# --- corruption, sequence numbers, THREAD_INFO -----------------------------------------------


@pytest.mark.parametrize("index", [2, 3, 4, *range(6, 60)])
def test_corrupted_frame_counts_one_crc_error_and_the_next_frame_decodes(index: int) -> None:
    encoder = Encoder()
    bad = bytearray(encoder.gpio(*GPIO_CART_TO_PC_ARGS))
    bad[index] ^= 0x10
    good = encoder.event(1001)
    framer = Framer()
    assert framer.feed(bytes(bad) + good) == [Event(1001, seq=1)]
    assert framer.stats.crc_errors == 1
    assert framer.stats.garbage_bytes == len(bad)
    assert framer.stats.frames == 1


@pytest.mark.parametrize("index", [0, 1, 5])
def test_corrupted_header_is_garbage(index: int) -> None:
    bad = bytearray(EVENT_1000)
    bad[index] ^= 0x01
    framer = Framer()
    assert framer.feed(bytes(bad) + HEARTBEAT_1234) == [Heartbeat(1234, 20, bytes(8), 2)]
    assert framer.stats.crc_errors == 0
    assert framer.stats.garbage_bytes == len(bad)


def test_sequence_gaps_and_lost_frames() -> None:
    encoder = Encoder()
    frames = [encoder.event(1000) for _ in range(10)]
    framer = Framer()
    framer.feed(b"".join(frames[:3] + frames[6:]))
    assert framer.stats.seq_gaps == 1
    assert framer.stats.lost_frames == 3
    assert framer.stats.frames == 7


def test_sequence_wraps_and_is_tracked_per_source() -> None:
    cart, other = Encoder(sysid=0), Encoder(sysid=1)
    cart.seq = 254
    other.seq = 100
    stream = b"".join([cart.event(1), other.event(2), cart.event(3), other.event(4), cart.event(5)])
    framer = Framer()
    messages = framer.feed(stream)
    assert [m.seq for m in messages] == [254, 100, 255, 101, 0]
    assert [m.sysid for m in messages] == [0, 1, 0, 1, 0]
    assert framer.stats.seq_gaps == 0
    cart.seq = 10
    framer = Framer()
    framer.feed(cart.event(0) + Encoder().event(0))  # seq 10 then 0: 245 lost
    assert framer.stats.lost_frames == 245


def test_thread_info_is_recognised_not_garbage() -> None:
    payload = bytes(range(22))
    framer = Framer()
    assert framer.feed(thread_info_frame(payload, seq=4) + EVENT_1000) == [
        ThreadInfo(payload, seq=4),
        Event(1000),
    ]
    assert framer.stats.garbage_bytes == 0
    assert framer.stats.seq_gaps == 1  # 4 then 0
    bad = bytearray(thread_info_frame(payload))
    bad[10] ^= 0xFF
    framer = Framer()
    assert framer.feed(bytes(bad) + EVENT_1000) == [Event(1000)]
    assert framer.stats.crc_errors == 1


# --- generation B ----------------------------------------------------------------------------


def test_generation_b_frames_are_recognised() -> None:
    frame = encode_gpiox_v2(17170, [float(i) for i in range(12)], seq=9, sysid=3, compid=1)
    framer = Framer()
    assert framer.feed(frame + frame) == [GenerationBFrame(14, 9, 3, 1)] * 2
    assert framer.stats.generation_b_frames == 2
    assert framer.stats.frames == 2
    assert framer.stats.garbage_bytes == 0
    assert framer.stats.seq_gaps == 0


def test_signed_generation_b_frame_is_recognised() -> None:
    frame = bytearray(encode_gpiox_v2(5, [1.0] * 12))
    frame[2] = 0x01  # incompat: signed; the CRC does not cover the flags' meaning, recompute it
    crc = x25crc(bytes(frame[1:-2]) + bytes([221])).crc
    frame[-2:] = crc.to_bytes(2, "little")
    framer = Framer()
    assert framer.feed(bytes(frame) + bytes(13) + EVENT_1000) == [GenerationBFrame(14), Event(1000)]
    assert framer.stats.garbage_bytes == 0


def test_other_or_corrupt_mavlink2_frames_are_garbage() -> None:
    frame = bytearray(encode_gpiox_v2(5, [1.0] * 12))
    corrupt = bytes(frame[:-1]) + bytes([frame[-1] ^ 1])
    other_id = bytes(frame[:7]) + bytes([15]) + bytes(frame[8:])
    framer = Framer()
    assert framer.feed(corrupt + other_id + EVENT_1000) == [Event(1000)]
    assert framer.stats.generation_b_frames == 0
    assert framer.stats.crc_errors == 0
    assert framer.stats.garbage_bytes == len(corrupt) + len(other_id)


def test_mixed_generations() -> None:
    encoder = Encoder()
    stream = (
        encoder.heartbeat(1)
        + encode_gpiox_v2(2, [0.5] * 12)
        + encoder.gpio(3, [0.0] * 8, [0] * 4)
        + b"\xfd\xfe\x00"
        + encode_gpiox_v2(4, [0.0] * 12, seq=1)
        + encoder.event(1003)
    )
    framer = Framer()
    kinds = [type(m) for m in framer.feed(stream)]
    assert kinds == [Heartbeat, GenerationBFrame, Gpio, GenerationBFrame, Event]
    assert framer.stats.garbage_bytes == 3
    assert framer.stats.generation_b_frames == 2
    assert framer.stats.seq_gaps == 0


# --- a long stream ---------------------------------------------------------------------------


def test_a_long_stream_of_gpio_frames_decodes_every_frame() -> None:
    """Frame after frame through one framer: each decodes, with its values, and nothing is
    garbage. (How fast: ``benchmarks/bench_speeds.py``.)"""
    frame = Encoder().gpio(*GPIO_CART_TO_PC_ARGS)
    framer = Framer()
    n = 500
    decoded = [m for _ in range(n) for m in framer.feed(frame)]
    assert framer.stats.frames == len(decoded) == n
    assert framer.stats.garbage_bytes == 0
    assert all(isinstance(m, Gpio) for m in decoded)
    assert decoded[0] == decoded[-1]
