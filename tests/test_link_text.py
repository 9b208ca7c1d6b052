"""PRINT fragments to lines."""

from __future__ import annotations

from cartctl.link import LineAssembler


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
