"""``.ci/run`` runs the README's test command in a fresh folder of its own and leaves ``.venv`` alone.

The script is run for real, on a small git checkout made here: the shipped ``.ci/run``, a README
whose Quickstart test command is cheap (it makes a ``.venv`` with stand-ins for ``ruff``, ``mypy``
and ``mkdocs`` and notes where it ran), a developer's ``.venv`` with a file in it, an untracked
file and an ignored one.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# the second line of the Quickstart block is the test command .ci/run reads (as in our README)
README = """# demo

## Quickstart

```sh
echo install-and-run
mkdir -p .venv/bin && for t in ruff mypy mkdocs; do printf '#!/bin/sh\\necho %s "$@" >> "$CI_LOG"\\n' $t > .venv/bin/$t && chmod +x .venv/bin/$t; done && pwd > "$CI_LOG.where" && ls > "$CI_LOG.files"
```
"""


def _git(repo: Path, *args: str) -> None:
    subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True)


@pytest.fixture
def checkout(tmp_path: Path) -> Path:
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    repo = tmp_path / "repo"
    (repo / ".ci").mkdir(parents=True)
    shutil.copy2(ROOT / ".ci" / "run", repo / ".ci" / "run")
    (repo / "README.md").write_text(README)
    (repo / ".gitignore").write_text(".venv/\nignored.txt\n")
    _git(repo, "init", "-q")
    _git(repo, "add", ".")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "demo")
    (repo / "untracked.txt").write_text("not committed yet\n")
    (repo / "ignored.txt").write_text("ignored\n")
    (repo / ".venv").mkdir()
    (repo / ".venv" / "developer-env").write_text("the developer's environment\n")
    return repo


def test_ci_runs_the_readme_command_elsewhere_and_keeps_the_developers_venv(
    checkout: Path, tmp_path: Path
) -> None:
    log = tmp_path / "ci.log"
    env = {**os.environ, "CI_LOG": str(log), "TMPDIR": str(tmp_path)}
    proc = subprocess.run([str(checkout / ".ci" / "run")], cwd=checkout, env=env,
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    where = Path(Path(f"{log}.where").read_text().strip())
    assert where != checkout and checkout not in where.parents
    files = set(Path(f"{log}.files").read_text().split())
    # the working tree as git sees it: tracked and untracked files, not ignored ones
    assert {"README.md", "untracked.txt"} <= files
    assert "ignored.txt" not in files
    # the developer's .venv is untouched, and the command's own .venv did not land in it
    assert (checkout / ".venv" / "developer-env").read_text() == "the developer's environment\n"
    assert not (checkout / ".venv" / "bin").exists()
    # the lint and the type check ran with the fresh environment's ruff and mypy, over the
    # project's folders, and the documentation was built strictly, into the copy's own folder
    assert log.read_text().splitlines() == [
        "ruff check src tests benchmarks tools",
        "ruff format --check src tests benchmarks tools",
        "mypy src",
        f"mkdocs build --strict --site-dir {where}/site",
    ]
    assert not where.exists()  # the folder is removed afterwards (CI_KEEP=1 keeps it)


def test_ci_fails_when_the_readme_has_no_test_command(checkout: Path, tmp_path: Path) -> None:
    (checkout / "README.md").write_text("# demo\n\nno quickstart here\n")
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    proc = subprocess.run([str(checkout / ".ci" / "run")], cwd=checkout, env=env,
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert proc.returncode != 0
    assert "could not find the test command" in proc.stderr
