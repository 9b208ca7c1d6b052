"""``cartctl monitor PLANT``: record and stream what a cart running its own controller sends,
passively (:mod:`cartctl.link.cart_monitor`): each GPIO frame one CSV row and one point per
channel under ``gpio/<label>``, PRINT lines and button events under ``cart/``."""

from __future__ import annotations

import argparse
import contextlib
import functools
import signal
import sys
import threading
from collections.abc import Iterator
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cartctl.cli.commands.options as options
from cartctl import stopping
from cartctl.choices import DEFAULT_CONNECT_TIMEOUT_S
from cartctl.cli.commands.virtual_cart import check_cart_options, onboard_firmware
from cartctl.errors import InputError

if TYPE_CHECKING:  # cartctl.plants loads numpy and scipy: imported where used, not for --help
    from cartctl.link.cart_monitor import Monitor

DEFAULT_REFERENCE = "step:10"
_STOPPED = {"duration": "after --duration", "interrupted": "by Ctrl-C", "fault": "by a line fault"}


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "monitor",
        help="record and stream the GPIO channels a cart sends (a cart running its own controller)",
        description="Record every GPIO frame a cart sends to a CSV trace and a Rerun recording "
        "(live in the viewer), with your channel labels, as QRoboticsCenter does. cartctl's own "
        "firmware (the bridge sketch, a controller of 'cartctl export --arduino') says so in "
        "float 6, and its channels are then named as trace columns (speed_a, voltage_a, "
        "reference_a, ...) without --labels. Passive: nothing is sent to the cart. Stops after "
        "--duration, on Ctrl-C (exit 0) or on a line fault (100 ms without data, the port gone: "
        "exit 1, the files hold what came before).",
    )
    p.add_argument(
        "plant", metavar="PLANT",
        help="serial:PORT (a cart, e.g. serial:/dev/ttyACM0) or virtual[:FAULTS] (the simulated "
        "cart behind a pseudo-terminal, in this process; FAULTS as for 'cartctl virtual-cart "
        "--faults', e.g. virtual:pull=2)",
    )  # fmt: skip
    p.add_argument(
        "--labels", metavar="KEY=LABEL,...",
        help="channel labels (CSV columns, Rerun entities gpio/LABEL), KEY f0..f7 or i0..i3, e.g. "
        "f0=speed_a,f1=speed_b,i0=echo; default: those of cartctl's firmware when the cart's "
        "frames say it runs the bridge or an exported controller (float 6), else FloatIn0..7, "
        "IntIn0..3 (QRoboticsCenter's)",
    )  # fmt: skip
    p.add_argument("--duration", type=float, metavar="S",
                   help="stop after S seconds of cart time (default: run until Ctrl-C)")  # fmt: skip
    options.add_output_options(p, name_default="monitor-DATE-TIME")
    options.add_rerun_options(p)
    p.add_argument(
        "--connect-timeout", type=float, default=DEFAULT_CONNECT_TIMEOUT_S, metavar="S",
        help=f"longest wait for the cart's HEARTBEAT (default {DEFAULT_CONNECT_TIMEOUT_S:g} s)",
    )  # fmt: skip
    p.add_argument(
        "--onboard", metavar="CONTROLLER.toml",
        help="virtual plant only: the cart runs this controller on board (as the C of 'cartctl "
        "export --arduino' does on a real cart)",
    )  # fmt: skip
    p.add_argument(
        "--reference", metavar="SPEC",
        help=f"with --onboard: the on-board reference of both motors (default {DEFAULT_REFERENCE})"
        f": {options.FORMS}",
    )  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> tuple[str, str]:
    """Validate the options; returns (kind, rest) of PLANT: ('serial', PORT) or ('virtual', FAULTS)."""
    kind, _, rest = args.plant.partition(":")
    if args.plant == "serial:":
        raise InputError("plant 'serial:' needs a port, e.g. serial:/dev/ttyACM0")
    if not (kind == "virtual" or (kind == "serial" and rest)):  # the plant first
        raise InputError(f"unknown plant '{args.plant}'; expected serial:PORT or virtual[:FAULTS]")
    check_cart_options(args)
    if kind == "serial" and (args.onboard or args.reference):
        raise InputError(
            "--onboard and --reference set up the virtual cart; a real cart runs the C of "
            "'cartctl export CONTROLLER.toml --arduino' with its own references"
        )
    if args.reference and not args.onboard:
        raise InputError("--reference needs --onboard CONTROLLER.toml")
    return kind, rest


def _rerun_sink(args: argparse.Namespace, path: Path) -> Any:
    from cartctl.link.dialect import GPIO_FLOAT_COUNT

    if args.rerun == "off":
        return None
    from cartctl.sinks.rerun_problems import resolve_mode
    from cartctl.sinks.rerun_sink import ChannelsRerunSink

    return ChannelsRerunSink(resolve_mode(args.rerun), path, float_count=GPIO_FLOAT_COUNT,
                             connect_url=args.connect_url)  # fmt: skip


@contextlib.contextmanager
def _stop_on_signals(monitor: Monitor, received: list[int]) -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP ask the monitor to stop after the current frame; a second
    SIGINT interrupts. The signals received go into ``received``."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        received.append(signum if received else stopping.came_first(signum))
        monitor.stop_requested = True
        signal.signal(signal.SIGINT, signal.default_int_handler)

    previous = {s: signal.signal(s, handler) for s in stopping.STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)


def run(args: argparse.Namespace) -> int:
    """0 (also after Ctrl-C), 1 on a fault, 128 + another stop signal's number."""
    with contextlib.ExitStack() as after:  # from the monitor's end to its summary: signals noted
        return _monitor(args, after)


def _monitor(args: argparse.Namespace, after: contextlib.ExitStack) -> int:
    from cartctl.cli.jsonout import dumps
    from cartctl.data.outputs import call_each, remove_stale_recording
    from cartctl.data.trace import meta_path
    from cartctl.link.cart_link import CartLink, print_to_stderr
    from cartctl.link.cart_monitor import Monitor, parse_labels
    from cartctl.runtime.realtime import gc_paused
    from cartctl.sinks.csv_sink import CsvSink

    kind, rest = _check(args)
    csv_path, rrd_path = options.check_run_outputs(args, "monitor")  # before a cart is connected
    try:
        labels = parse_labels(args.labels) if args.labels is not None else None
    except InputError as exc:
        raise InputError(f"--labels: {exc}") from None
    cart: Any = None
    if kind == "virtual":
        from cartctl.link.virtual_cart import SILENCE_TIMEOUT_S, CartFaults, VirtualCart

        faults = CartFaults.parse(rest)  # before --onboard's controller is loaded
        reference = args.reference or DEFAULT_REFERENCE
        cart = VirtualCart(faults=faults, firmware=onboard_firmware(args, reference))
    port = cart.port if cart is not None else rest
    announce = functools.partial(print, file=sys.stderr, flush=True)
    monitor = Monitor([], [], labels, echo=print_to_stderr, announce=announce)
    received: list[int] = []
    link = CartLink(port, on_event=monitor.on_event, on_print=monitor.on_print)
    if cart is not None:  # the virtual cart's rate is known: the bridge's, or the course's
        link.baud = cart.baud
        link.silence_timeout_s = SILENCE_TIMEOUT_S  # it shares this process: see there
    try:
        link.open()  # before the virtual cart boots: its first HEARTBEAT is not flushed away
        if cart is not None:
            cart.start()
        # no file is opened for a cart that is not there
        link.wait_heartbeat_any_rate(args.connect_timeout)
        if cart is not None:  # its faults count from the host's first frame; a monitor sends none
            cart.arm_faults()
        rerun = _rerun_sink(args, rrd_path)
        monitor.rows.append(CsvSink(csv_path))
        with contextlib.suppress(OSError):  # a run's of this name would describe its trace here
            meta_path(csv_path).unlink(missing_ok=True)
        if rerun is None:  # and its recording would pass for this one
            remove_stale_recording(csv_path)
        if rerun is not None:
            monitor.rows.append(rerun)
            monitor.texts.append(rerun)
        try:
            # the sinks open at the first frames; a collection walks only the objects made meanwhile
            with _stop_on_signals(monitor, received), gc_paused(collect_new=True):
                result = monitor.run(link, args.duration)
        finally:  # its own handlers are gone: a signal must not cut the closing short
            after.enter_context(stopping.deferred())
            call_each([sink.close for sink in monitor.rows])  # each closed; a failure raised after
    finally:
        link.close()
        if cart is not None:
            cart.stop()
    stats = link.stats.to_dict()
    stats.pop("generation_b_frames", None)
    summary = {
        **asdict(result),
        "plant": args.plant,
        "port": link.port,
        "firmware": monitor.firmware.name if monitor.firmware is not None else None,
        "labels": list(monitor.labels or ()),
        "link": stats,
        "trace": str(csv_path),
        "recording": str(rrd_path) if rerun is not None else None,
    }
    try:
        print(dumps(summary) if args.json else _format(summary))
        if result.failure:
            print(f"cartctl monitor: error: {result.failure}", file=sys.stderr)
    except OSError:  # stdout and stderr gone with a closed terminal (EIO): the files are whole,
        if not received:  # and the code below says which signal stopped it
            raise
    if result.failure:
        return 1
    signum = received[0] if received else stopping.received()  # while it ran, or after it
    return 0 if signum in (None, signal.SIGINT) else 128 + signum  # Ctrl-C: the normal way


def _format(summary: dict[str, Any]) -> str:
    link = summary["link"]
    lines = [
        f"monitor {summary['plant']}: {summary['frames']} frames over {summary['duration_s']:.2f} s "
        f"of cart time, stopped {_STOPPED[summary['stopped']]}",
        f"  link: {link['frames']} frames, {link['crc_errors']} CRC errors, "
        f"{link['garbage_bytes']} garbage bytes, {link['lost_frames']} lost frames "
        f"({link['seq_gaps']} gaps)",
        f"  cart: {summary['print_lines']} PRINT lines, {summary['events']} events",
        f"  trace {summary['trace']}",
    ]
    if summary["recording"]:
        lines.append(f"  recording {summary['recording']}")
    return "\n".join(lines)
