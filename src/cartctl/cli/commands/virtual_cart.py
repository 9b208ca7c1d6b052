"""``cartctl virtual-cart``: the physical simulator behind a pseudo-terminal, until Ctrl-C."""

from __future__ import annotations

import argparse
import math
import signal
import sys
from typing import TYPE_CHECKING

import cartctl.cli.commands.options as options
from cartctl import stopping
from cartctl.errors import InputError

if TYPE_CHECKING:
    from cartctl.link.cart_faults import CartFaults
    from cartctl.link.firmware import OnboardFirmware


def _faults(text: str) -> CartFaults:
    from cartctl.link.cart_faults import CartFaults

    try:
        return CartFaults.parse(text)
    except ValueError as exc:  # InputError: argparse shows the message as one line
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "virtual-cart",
        help="serve the simulated cart on a pseudo-terminal, as the bridge firmware would",
        description="Run the physical simulator behind a pseudo-terminal that speaks the cart's "
        "microOS MAVLink protocol and the bridge contract (firmware/): 100 GPIO frames per second "
        "at 500 kbaud (115200 with --onboard or --faults bridge=1), a HEARTBEAT every 1.1 s, the "
        "watchdog. Prints the port; point 'cartctl run --plant serial:PORT', 'excite' or "
        "'monitor' at it. Ctrl-C stops it.",
    )
    p.add_argument(
        "--preset", choices=("air", "ground"), default="ground",
        help="wheels in the air or cart on the ground (default ground)",
    )  # fmt: skip
    p.add_argument("--noise", type=float, default=0.0, metavar="RAD_S",
                   help="extra measurement noise, standard deviation in rad/s (default 0)")  # fmt: skip
    p.add_argument(
        "--seed", type=options.seed, default=None, help="seed of the noise and the faults"
    )
    p.add_argument(
        # a string default goes through type when parsed: CartFaults(), without loading numpy here
        "--faults", type=_faults, default="", metavar="KEY=VALUE,...",
        help="inject faults: garbage=FRACTION (bursts of random bytes before that fraction of "
        "frames), corrupt=FRACTION (frames with a changed byte), stall=S (stop ticking S seconds "
        "after the host's first frame, port open), pull=S (the port vanishes S seconds after the "
        "host's first frame), late=FRACTION (that fraction of the ticks, in stretches of 5, take "
        "the host's commands a tick late), generation=b (speak the "
        "newer MAVLink 2 firmware instead), reverse_a=1 / reverse_b=1 (that motor wired "
        "backwards: + volts turn it the negative way); the cart itself: actuation_ms=X (a command "
        "on the wheels X ms after its tick, 0 < X <= 10, default 3), usb=off, bridge=1, "
        "receive=microos, reply_jitter_ms=J (docs/serial-protocol.md §8)",
    )  # fmt: skip
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--onboard", metavar="CONTROLLER.toml",
        help="run this controller on the cart instead of the bridge sketch, as the C of 'cartctl "
        "export --arduino' does (one tick of delay); out channels: float 0/1 speed A/B, 2/3 "
        "voltage A/B, 4/5 reference A/B",
    )  # fmt: skip
    p.add_argument(
        "--reference", metavar="SPEC",
        help=f"with --onboard: the reference of both motors, {options.FORMS}; default: the float "
        "channels 0 (A) and 1 (B) the host sends, held between frames, as the exported C reads them",
    )  # fmt: skip
    p.set_defaults(func=run)


def check_cart_options(args: argparse.Namespace) -> None:
    """``--duration``, the plant's options and ``--reference`` (``monitor`` checks them too)."""
    if args.duration is not None:
        options.check_duration(args.duration)
    options.check_plant_options(args)
    if args.reference:
        from cartctl.reference import check_reference

        check_reference(args.reference)


def onboard_firmware(args: argparse.Namespace, reference: str | None) -> OnboardFirmware | None:
    """The firmware running ``--onboard``'s controller with ``reference`` (None: the bridge's)."""
    if not args.onboard:
        return None
    from cartctl.export.arduino import onboard_controllers
    from cartctl.link.firmware import OnboardFirmware

    controllers = onboard_controllers(args.onboard)
    if reference:
        _check_reach(args.onboard, reference, args.duration)
    return OnboardFirmware(controllers, reference=reference)


def _check_reach(path: str, spec: str, duration_s: float | None) -> None:
    """Refuse a reference far beyond what the controller's model reaches, as ``run`` does (over
    the run, or its first minute): 1e308 overflowed the cart's float channels in its thread; and
    a step after the run, as ``run`` does."""
    from cartctl.cart import PERIOD_S
    from cartctl.data.modelfile import load_models
    from cartctl.design.controllerfile import load_controller
    from cartctl.errors import CartctlError
    from cartctl.reference import ReferenceSchedule, check_step_in_run
    from cartctl.session.prepare import check_reach

    if duration_s:  # the cart's ticks before --duration (monitor's frames: 0.104 s holds 0.10 s)
        check_step_in_run(spec, math.ceil((duration_s - 1e-9) / PERIOD_S), PERIOD_S, "--reference")
    controller = load_controller(path)
    try:
        models = dict(load_models(controller.model_path).motors)
    except (CartctlError, OSError):  # the model moved: nothing to measure the reference by
        return
    n = round(min(duration_s or 60.0, 60.0) / PERIOD_S)
    references = {m: ReferenceSchedule(spec, n, PERIOD_S, m) for m in controller.motors}
    check_reach(references, models, controller.voltage_limit_v, controller.model_path)


def run(args: argparse.Namespace) -> int:
    from cartctl.link.virtual_cart import VirtualCart

    if args.reference and not args.onboard:
        raise InputError("--reference needs --onboard CONTROLLER.toml")
    check_cart_options(args)
    cart = VirtualCart(args.preset, noise_std_rad_s=args.noise, seed=args.seed, faults=args.faults,
                       firmware=onboard_firmware(args, args.reference))  # fmt: skip
    try:  # a stop signal from the port's line on: the cart's own stop line too
        print(cart.port, flush=True)
        running = f"the bridge sketch version {cart.bridge_version}"
        if cart.faults.generation == "b":
            running = "microOS generation B (MAVLink 2)"
        if args.onboard:
            running = f"controller {args.onboard} on board"
        usb = "modelled" if cart.faults.usb else "off"
        timing = cart.physics.params.actuation_delay() * 1000.0
        example = "monitor serial:" if args.onboard else "run --plant serial:"
        print(
            f"virtual cart (physics preset {args.preset}, {running}, {cart.baud} baud, USB chip "
            f"{usb}, commands land {timing:g} ms after their tick) on {cart.port}; e.g. cartctl "
            f"{example}{cart.port}; Ctrl-C stops it",
            file=sys.stderr,
            flush=True,
        )
        cart.start()  # not ``with cart``: a signal inside start() would skip its stop()
        cart.wait(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        with stopping.deferred():  # a signal now waits until the cart is off
            cart.stop()
    print(f"virtual cart stopped ({cart.state}) after {cart.ticks} ticks", file=sys.stderr)
    signum = stopping.received()  # Ctrl-C is the way to stop it; SIGTERM, SIGHUP say so, as monitor
    return 0 if signum in (None, signal.SIGINT) else 128 + signum
