"""A trace that cannot be created once the plant is ready (its folder removed and made a file since
the output check, a full disk): one line naming the file, exit 1, zero volts. ``excite`` raised
IndexError (its trace's columns looked up from an open that never happened) and ``run`` called
it an internal error."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import cartctl.plants.factory
from cartctl.cli import main


def _folder_made_a_file(make_plant: Callable[..., Any]) -> Callable[..., Any]:
    def make(*args: Any, **kwargs: Any) -> Any:
        made = make_plant(*args, **kwargs)
        shutil.rmtree("sub")
        Path("sub").write_text("a file now\n", encoding="utf-8")
        return made

    return make


@pytest.mark.parametrize("command", ["excite", "run"])
def test_a_trace_that_cannot_be_created_is_one_line(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    command: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("sub").mkdir()
    factory = cartctl.plants.factory
    monkeypatch.setattr(factory, "make_plant", _folder_made_a_file(factory.make_plant))
    if command == "excite":
        argv = ["excite", "--amplitude", "5", "--cycles", "1", "--out", "sub/e.csv"]
    else:
        argv = [
            "run",
            "--fast",
            "--duration",
            "0.3",
            "--rerun",
            "off",
            "--out",
            "sub",
            "--name",
            "e",
        ]
    code = main(argv)
    (line,) = capsys.readouterr().err.splitlines()
    assert code == 1, line
    assert line.startswith(f"cartctl {command}: error: sub/e.csv is incomplete: "), line
    assert "internal error" not in line
    assert Path("sub").read_text(encoding="utf-8") == "a file now\n"
