"""The ``cartctl`` command line: parses arguments, runs a subcommand of
:mod:`cartctl.cli.commands`, and turns a user's mistake into one line on stderr and exit code 2."""

import os
import sys

from cartctl import stopping


def _started_as_cartctl() -> bool:
    """Whether this process is the ``cartctl`` program, not a Python program importing it."""
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    if spec is not None:
        return bool(spec.name.partition(".")[0] == "cartctl")
    return os.path.basename(getattr(main, "__file__", None) or "").startswith("cartctl")


if _started_as_cartctl():  # before any other import: a stop signal from here on is one line
    stopping.install_at_start()

import argparse  # noqa: E402 - the stop handlers come first
import contextlib  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from typing import NoReturn  # noqa: E402

from cartctl import __version__  # noqa: E402
from cartctl.errors import CartctlError  # noqa: E402


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line (plus where to look) and exit code 2, and
    arguments no option takes are reported by their subcommand (``cartctl run: error: …``)."""

    subcommands: dict[str, argparse.ArgumentParser] = {}  # noqa: RUF012 - set per instance

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")

    def parse_args(self, args=None, namespace=None):
        parsed, extra = self.parse_known_args(args, namespace)
        if extra:
            owner = self.subcommands.get(getattr(parsed, "command", None) or "", self)
            owner.error(f"unrecognized arguments: {' '.join(extra)}")
        return parsed


def command_name(module: object) -> str:
    """The subcommand a module of :mod:`cartctl.cli.commands` adds (``virtual_cart``: ``virtual-cart``)."""
    return str(getattr(module, "__name__", "")).rpartition(".")[2].replace("_", "-")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser with ``command`` alone (a tenth of the time), or with every subcommand when
    ``command`` is None or names none."""
    parser = _Parser(
        prog="cartctl",
        description="Identify, design and run velocity control of a two-wheeled DC-motor cart. "
        "Workflow: excite → identify → design → run → review.",
    )
    parser.add_argument("--version", action="version", version=f"cartctl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    from cartctl.cli.commands import COMMANDS  # light: each command loads numpy & co. when it runs

    for module in [m for m in COMMANDS if command_name(m) == command] or COMMANDS:
        module.add_parser(sub)
    parser.subcommands = dict(sub.choices)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; the exit code (0 ok, 2 user mistake, 1 runtime failure, 130, 143 or
    129 after SIGINT, SIGTERM or SIGHUP)."""
    handlers: dict[int, object] = {}
    try:
        handlers = stopping.install()
        return _main(argv)
    except KeyboardInterrupt:  # in the few instructions around _main's own handling
        print("cartctl: interrupted", file=sys.stderr)
        return stopping.exit_code()
    finally:
        stopping.restore(handlers)


def console_main() -> int:
    """The ``cartctl`` program: :func:`main`, then stop signals ignored until the process ends
    (one arriving while the Rerun SDK flushes at exit must not cut it short)."""
    stopping.install_at_start()  # already done on import, unless another launcher imported us
    # one BLAS thread unless the user asks for more, read when numpy loads (later: the parser
    # loads no numpy): cartctl's matrices are a few states wide, more threads only spin
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    try:
        return main()
    finally:
        stopping.ignore()


def _main(argv: Sequence[str] | None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    named = next((word for word in words if not word.startswith("-")), None)
    try:
        parser = build_parser(named)  # an unknown command, or none, gets the full parser
    except KeyboardInterrupt:
        print(stopping.STARTING_LINE, file=sys.stderr)
        return stopping.exit_code()
    args = parser.parse_args(words)
    from cartctl.sinks.rerun_problems import quiet_sdk_logs

    quiet_sdk_logs()  # before any command loads the Rerun SDK: its failures are ours to say
    previous = warnings.showwarning
    warnings.showwarning = lambda message, *_, **__: print(  # one line: cartctl CMD: warning: …
        f"cartctl {args.command}: warning: {message}", file=sys.stderr
    )
    from cartctl.runtime.realtime import one_blas_thread

    try:
        with one_blas_thread():  # restored afterwards
            return int(args.func(args))
    except CartctlError as exc:
        print(f"cartctl {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # output piped into a command that stopped reading (| head)
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - keeps the interpreter's flush quiet
        return 0
    except OSError as exc:  # a file we could not write or read for a reason the user can fix
        reason = f"{exc.strerror or exc}: {exc.filename or ''}".rstrip(": ")
        with contextlib.suppress(OSError):  # stderr gone with a closed terminal (EIO)
            print(f"cartctl {args.command}: error: {reason}", file=sys.stderr)
        return stopping.exit_code(2)  # SIGHUP's code when the terminal closed
    except (KeyboardInterrupt, Exception) as exc:
        # Ctrl-C or a stop signal; after a stop signal, also a library's error of its own (pyarrow's
        # compiled code: a TypeError), or an ImportError: the command's heavy imports come first
        # in its run(), and a signal inside an extension module's initialisation surfaces as its
        # ImportError, before anything was done.
        if not isinstance(exc, KeyboardInterrupt) and stopping.received() is None:
            raise
        line = f"cartctl {args.command}: interrupted"
        print(stopping.STARTING_LINE if isinstance(exc, ImportError) else line, file=sys.stderr)
        return stopping.exit_code()
    finally:
        warnings.showwarning = previous


if __name__ == "__main__":
    raise SystemExit(console_main())
