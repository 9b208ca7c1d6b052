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
