"""PRINT fragments to lines."""

from __future__ import annotations

from cartctl.link.dialect import LineAssembler


def test_lines_are_stitched_across_fragments() -> None:
    lines = LineAssembler()
    assert lines.feed("Robot en") == []
    assert lines.feed("abled.\r\nNext") == ["Robot enabled."]
    assert lines.flush() == "Next"
    assert lines.flush() is None


def test_line_endings() -> None:
    lines = LineAssembler()
    assert lines.feed("a\r") == []
    assert lines.feed("\nb\nc\r\n\r\nd\re") == ["a", "b", "c", ""]
    assert lines.flush() == "de"


def test_several_fragments_make_one_line() -> None:
    lines = LineAssembler()
    for part in ["x" * 32, "y" * 32, "z"]:
        assert lines.feed(part) == []
    assert lines.feed("\r\n") == ["x" * 32 + "y" * 32 + "z"]
    assert lines.flush() is None


def test_a_long_unfinished_line_costs_each_fragment_only_its_own_size() -> None:
    """A firmware that never ends its lines (or ends them with "\\r" alone, which is dropped) sends
    PRINT frames for as long as it runs: taking one more 32-byte piece must not copy the text held
    so far (on the host's receive path that would grow into milliseconds per frame)."""
    import tracemalloc

    lines = LineAssembler()
    piece = "p" * 31 + "\r"
    for _ in range(16_000):  # 0.5 MB held: about 3 minutes of one PRINT frame per 10 ms tick
        lines.feed(piece)
    tracemalloc.start()
    try:
        assert lines.feed(piece) == []
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50_000, f"one fragment allocated {peak} bytes with 0.5 MB held"
    assert lines.feed("\n") == ["p" * 31 * 16_001]


class _Port:
    """pyserial's surface over a fixed byte string (what the cart sent before the host closed)."""

    def __init__(self, data: bytes) -> None:
        self.data = bytearray(data)

    @property
    def in_waiting(self) -> int:
        return len(self.data)

    def read(self, size: int = 1) -> bytes:
        out = bytes(self.data[:size])
        del self.data[:size]
        return out

    def flush(self) -> None:
        pass

    def close(self) -> None:
        pass


def test_a_last_print_without_a_newline_is_shown_when_the_link_closes() -> None:
    # the link kept it as an unfinished line and dropped it when the port closed
    from cartctl.link.cart_link import CartLink
    from cartctl.link.dialect import Encoder

    encoder = Encoder()
    sent = b"".join([*encoder.print_text("ready\n"), *encoder.print_text("stopped"),
                     encoder.heartbeat(0)])  # fmt: skip
    shown: list[str] = []
    link = CartLink("/dev/fake", on_print=shown.append, serial_factory=lambda *a, **k: _Port(sent))
    link.open()
    assert link.wait_heartbeat_any_rate(1.0)
    assert shown == ["ready"]
    link.close()
    assert shown == ["ready", "stopped"]
    link.close()  # a second close shows nothing twice
    assert shown == ["ready", "stopped"]
