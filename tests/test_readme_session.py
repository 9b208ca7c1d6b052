"""The README's "A session without a cart", run as written: from the experiment to a run of the
user's own model on the physics plant, with no refusal and at most 5 % overshoot.

The commands are read from README.md, so the README cannot drift from what is tested.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from cartctl.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"
SECTION = "### A session without a cart"


def session_commands() -> list[list[str]]:
    """The ``cartctl`` lines of the section's first shell block, split as a shell would."""
    text = README.read_text(encoding="utf-8")
    section = text.split(SECTION, 1)[1]
    block = section.split("```sh", 1)[1].split("```", 1)[0]
    lines = [line.strip() for line in block.splitlines() if line.strip().startswith("cartctl ")]
    return [shlex.split(line)[1:] for line in lines]


def test_the_session_has_the_whole_path() -> None:
    commands = [argv[0] for argv in session_commands()]
    assert commands[0] == "excite"
    assert {"identify", "design", "run"} <= set(commands)
    assert commands.index("identify") < commands.index("design") < commands.index("run")


def test_readme_session_runs_to_a_controller_within_5_percent(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)  # a fresh folder: no models/ or controllers/ of the checkout
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):  # the run's --rerun auto: record, no viewer
        monkeypatch.delenv(name, raising=False)
    summary = None
    for argv in session_commands():
        if argv[0] == "run":
            argv = [*argv, "--json"]
        code = main(argv)
        out, err = capsys.readouterr()
        assert code == 0, f"cartctl {shlex.join(argv)}: {err}"
        assert "refus" not in err.lower()
        if argv[0] == "run":
            summary = json.loads(out)
    assert summary is not None
    # the recording knew its loop and the model carries it (1 tick on the physics plant)
    meta = (tmp_path / "logs" / "ground.meta.toml").read_text(encoding="utf-8")
    assert "loop_delay_ticks = 1" in meta
    assert "loop_delay_ticks = 1" in (tmp_path / "models" / "mine.toml").read_text()
    assert summary["loop_delay_ticks"] == 1
    for motor in ("a", "b"):
        m = summary["motors"][motor]
        assert m["overshoot_percent"] <= 5.0, (motor, m)
        assert m["settling_time_s"] is not None, (motor, m)
