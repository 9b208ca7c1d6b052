"""Build step of cartctl's wheel and sdist: the shipped model and controller files, by name.

``models/`` and ``controllers/`` live at the top of the repository, where users and the firmware
tools look for them, next to the user's own files (``models/mine.toml``). Only the files named in
:data:`cartctl.choices.SHIPPED_FILES` are cartctl's: the sdist carries them, and the wheel copies
them to ``cartctl/shipped/`` so that a plain ``pip install`` has them too
(:func:`cartctl.choices.find_file` finds them there and, in an editable install, in the checkout
itself). Everything else is in ``pyproject.toml``.
"""

from __future__ import annotations

import importlib.util
import shutil
from collections.abc import Mapping
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

ROOT = Path(__file__).resolve().parent


def shipped_files() -> Mapping[str, tuple[str, ...]]:
    """``cartctl.choices.SHIPPED_FILES``, read from the source without importing the package."""
    spec = importlib.util.spec_from_file_location(
        "_cartctl_choices", ROOT / "src" / "cartctl" / "choices.py"
    )
    if spec is None or spec.loader is None:
        raise ImportError("setup.py: cannot read src/cartctl/choices.py")
    choices = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(choices)
    return choices.SHIPPED_FILES


def shipped_paths() -> list[str]:
    """The shipped files' paths relative to the repository (``models/ground.toml`` …)."""
    return [f"{folder}/{name}" for folder, names in shipped_files().items() for name in names]


class BuildWithShippedFiles(build_py):
    """``build_py``, plus the shipped model and controller files as package data."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):  # the checkout's own files are found in place
            return
        for relative in shipped_paths():
            source = ROOT / relative
            if not source.is_file():
                raise FileNotFoundError(f"a shipped file is missing from the source: {relative}")
            target = Path(self.build_lib) / "cartctl" / "shipped" / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)


class SdistWithShippedFiles(sdist):
    """``sdist``, plus the shipped files (so a wheel built from the sdist has them)."""

    def make_distribution(self) -> None:
        self.filelist.extend(shipped_paths())
        super().make_distribution()


setup(cmdclass={"build_py": BuildWithShippedFiles, "sdist": SdistWithShippedFiles})
