"""A stop signal while ``cartctl`` starts: one line and the signal's exit code, never a traceback.

Deterministic: the installed console script runs with a one-line prelude that makes the process
send itself the signal at a fixed moment, the first time a given module is imported (an import
hook), instead of a timer racing the start. The moments run from the first import after the stop
handlers to a command's own heavy imports.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from cartctl import __version__

HOOK = """\
import os as _os, sys as _s
class _SignalAt:
    @staticmethod
    def find_spec(name, path=None, target=None):
        if name == {module!r}:
            _s.meta_path.remove(_SignalAt)
            _os.kill(_os.getpid(), {signum})
_s.meta_path.insert(0, _SignalAt)
"""


@pytest.fixture(scope="module")
def console_script() -> Path:
    beside = Path(sys.executable).parent / "cartctl"
    found = beside if beside.exists() else shutil.which("cartctl")
    if found is None:
        pytest.skip("no cartctl console script installed")
    return Path(found)


def _start_with_signal(
    console_script: Path, folder: Path, module: str, signum: int, *argv: str
) -> subprocess.CompletedProcess[str]:
    """The console script, with the process signalling itself on importing ``module``."""
    body = console_script.read_text(encoding="utf-8").splitlines(keepends=True)
    shebang = body[:1] if body and body[0].startswith("#!") else []
    script = folder / "cartctl"  # its name, as the console script's: the program starts
    script.write_text(
        "".join([*shebang, HOOK.format(module=module, signum=int(signum)), *body[len(shebang) :]]),
        encoding="utf-8",
    )
    return subprocess.run([sys.executable, str(script), *argv], cwd=folder, text=True,
                          capture_output=True, timeout=60)  # fmt: skip


# (module imported when the signal comes, command line): from the first import after the stop
# handlers (argparse) through the rest of cartctl.cli's imports, the command modules the parser
# loads, to a command's own imports once it runs (numpy, in inspect)
MOMENTS = [
    ("argparse", ["--version"]),
    ("warnings", ["--version"]),
    ("pathlib", ["--version"]),
    ("cartctl.errors", ["run", "--help"]),
    ("cartctl.cli.commands", ["run", "--help"]),
    ("cartctl.cli.commands.run", ["run", "--help"]),
    ("numpy", ["inspect", "models/ground.toml"]),
]


@pytest.mark.parametrize(("module", "argv"), MOMENTS, ids=[m for m, _ in MOMENTS])
def test_sigint_at_a_start_up_moment_is_one_line_and_exit_130(
    console_script: Path, tmp_path: Path, module: str, argv: list[str]
) -> None:
    if module == "numpy":
        shutil.copytree(Path(__file__).resolve().parents[1] / "models", tmp_path / "models")
    done = _start_with_signal(console_script, tmp_path, module, signal.SIGINT, *argv)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 130, (done.returncode, done.stderr)
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cartctl"), done.stderr
    assert done.stdout == ""  # nothing was done: no version, no help, no poles


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_and_sighup_while_importing_exit_with_their_codes(
    console_script: Path, tmp_path: Path, signum: int, code: int
) -> None:
    done = _start_with_signal(console_script, tmp_path, "pathlib", signum, "--version")
    assert (done.returncode, "Traceback" in done.stderr) == (code, False), done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_without_a_signal_the_hooked_script_runs_as_usual(
    console_script: Path, tmp_path: Path
) -> None:
    """The prelude itself changes nothing: a module never imported sends no signal."""
    done = _start_with_signal(console_script, tmp_path, "no.such.module", signal.SIGINT,
                              "--version")  # fmt: skip
    assert (done.returncode, done.stdout.strip(), done.stderr) == (0, f"cartctl {__version__}", "")


def test_importing_the_cli_in_another_program_leaves_its_signals_alone() -> None:
    """Only the cartctl program routes the stop signals at import; a library user keeps its own."""
    code = (
        "import signal; before = signal.getsignal(signal.SIGTERM); import cartctl.cli; "
        "print(signal.getsignal(signal.SIGTERM) is before)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)  # fmt: skip
    assert done.stdout.strip() == "True"
