"""Subcommands whose options are fixed by contract 2 but whose work is not built yet.

They parse their contract options (so ``--help`` documents them) and then say plainly that the
command is not built yet, with exit code 2. Each moves to a module of its own when it is built.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass

from cartctl.errors import CartctlError


class NotBuiltError(CartctlError):
    """The command exists in the interface but its work has not landed yet."""


@dataclass(frozen=True)
class PendingCommand:
    """A subcommand that parses its options and reports that it is not built yet."""

    name: str
    help: str
    stage: str
    options: Callable[[argparse.ArgumentParser], None]

    def add_parser(self, sub: argparse._SubParsersAction) -> None:
        parser = sub.add_parser(self.name, help=self.help, description=self.help)
        self.options(parser)
        parser.set_defaults(func=self.run)

    def run(self, args: argparse.Namespace) -> int:
        raise NotBuiltError(
            f"'cartctl {self.name}' is not built yet (it arrives with the {self.stage})"
        )


def _run(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plant", default="sim", metavar="PLANT")
    p.add_argument("--controller", metavar="CONTROLLER.toml")
    p.add_argument("--reference", metavar="SPEC")
    p.add_argument("--duration", type=float, metavar="S")
    p.add_argument("--fast", action="store_true")
    p.add_argument("--rerun", metavar="MODE")
    p.add_argument("--out", metavar="DIR")
    p.add_argument("--json", action="store_true")


def _review(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="FILE.rrd")


run = PendingCommand("run", "run the 10 ms closed loop against a plant", "10 ms loop", _run)
review = PendingCommand("review", "open a recorded run in the Rerun viewer", "10 ms loop", _review)
