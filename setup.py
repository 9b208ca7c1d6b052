"""Build step of cartctl's wheel: the shipped model and controller files go into the package.

``models/`` and ``controllers/`` live at the top of the repository, where users and the firmware
tools look for them. When the wheel is built they are copied to ``cartctl/shipped/`` so that a
plain ``pip install`` has them too; :func:`cartctl.choices.find_file` finds them there (and, in an
editable install, in the checkout itself). Everything else is in ``pyproject.toml``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

SHIPPED_FOLDERS = ("models", "controllers")  # as cartctl.choices.SHIPPED_FOLDERS


class BuildWithShippedFiles(build_py):
    """``build_py``, plus ``models/*.toml`` and ``controllers/*.toml`` as package data."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):  # the checkout's own files are found in place
            return
        root = Path(__file__).resolve().parent
        for folder in SHIPPED_FOLDERS:
            target = Path(self.build_lib) / "cartctl" / "shipped" / folder
            target.mkdir(parents=True, exist_ok=True)
            for source in sorted((root / folder).glob("*.toml")):
                shutil.copy2(source, target / source.name)


setup(cmdclass={"build_py": BuildWithShippedFiles})
