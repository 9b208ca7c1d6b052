"""``cartctl commission PLANT [--out DIR]``: from a connected cart to a verified controller (the
stages of :mod:`cartctl.commission`); exit 0 verified, 1 a stage failed, 2 bad input, 128 + signal."""

from __future__ import annotations

import argparse
import contextlib
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

import cartctl.cli.commands.options as options
from cartctl import stopping
from cartctl.choices import DEFAULT_CONNECT_TIMEOUT_S
from cartctl.errors import CartctlError, InputError

COMMISSIONED = ("physics", "virtual", "serial")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "commission",
        help="one command from a connected cart to a verified controller",
        description="Commission a cart in five stages, each written to --out: (1) checks: the "
        "port, the cart's heartbeat and loop delay, each motor's direction and encoder sign (a "
        "short pulse) and breakaway voltage (a slow ramp); (2) the report's square excitation at "
        "an amplitude the checks chose; (3) ARX identification validated on the last 30 % of it; "
        "(4) robust pole-placement tuning on the model's uncertainty and on its commands landing "
        "2 and 4 ms later; (5) a closed-loop 10 rad/s step on the cart with the chosen "
        "controller, measured against the prediction. Writes model.toml, controller.toml, "
        "summary.md with tables and figures, and one .rrd per stage. Exit 0: verified; 1: a stage "
        "failed (one line says why; the files so far are kept); 2: bad input.",
    )
    p.add_argument("plant", metavar="PLANT",
                   help="physics[:OPTIONS] (the simulator, not in real time; physics:reverse_b=1 "
                        "wires motor b backwards), virtual[:OPTIONS] (the simulator behind a "
                        "pseudo-terminal, in real time: virtual:actuation_ms=10, "
                        "virtual:reverse_b=1 …) or serial:PORT (the cart)")  # fmt: skip
    p.add_argument("--out", metavar="DIR",
                   help="folder for everything written (default logs/commission-DATE-TIME); "
                        "must not hold an earlier commissioning")  # fmt: skip
    p.add_argument("--preset", action=options.Given, choices=("air", "ground"), default="ground",
                   help="physics and virtual: wheels in the air or cart on the ground (default "
                        "ground)")  # fmt: skip
    p.add_argument("--noise", action=options.Given, type=float, default=0.0, metavar="RAD_S",
                   help="physics and virtual: extra white measurement noise (rad/s, default 0)")  # fmt: skip
    p.add_argument(
        "--seed",
        action=options.Given,
        type=options.seed,
        default=None,
        help="seed of the measurement noise",
    )
    p.add_argument("--connect-timeout", action=options.Given, type=float, metavar="S",
                   default=DEFAULT_CONNECT_TIMEOUT_S,
                   help="serial and virtual carts: longest wait for the first HEARTBEAT "
                        "(default 5 s)")  # fmt: skip
    p.add_argument("--jobs", type=int, metavar="N",
                   help=f"worker processes of the tuning, 1..{options.MAX_JOBS} (default: 2 at most)")  # fmt: skip
    p.add_argument("--json", action="store_true",
                   help="print one JSON object: model, controller, verification (and the checks)")  # fmt: skip
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> Path:
    """Every option, in one line (exit 2) before anything is written; the output folder."""
    from cartctl.plants.factory import check_plant_name, plant_kind

    if plant_kind(args.plant) not in COMMISSIONED:
        raise InputError(f"PLANT must be physics[:OPTIONS], virtual[:OPTIONS] or serial:PORT, "
                         f"got '{args.plant}' (sim is a model already)")  # fmt: skip
    options.check_plant_options(args, "PLANT")
    options.check_jobs(args.jobs)
    default = datetime.now().strftime("logs/commission-%Y%m%d-%H%M%S")
    out = options.check_output_folder(args.out or default, "--out")
    earlier = [n for n in ("summary.md", "model.toml", "controller.toml") if (out / n).exists()]
    if earlier:
        raise InputError(f"--out {out} already holds {earlier[0]} of an earlier commissioning; "
                         "give another folder")  # fmt: skip
    if check_plant_name(args.plant) == "serial":  # its options, and the port of serial:PORT
        from cartctl.link.cart_link import check_port

        check_port(args.plant.partition(":")[2])
    return out


def run(args: argparse.Namespace) -> int:
    from cartctl.cli.jsonout import dumps
    from cartctl.commission import StageError
    from cartctl.commission.stages import Commission, StageStoppedError

    out = _check(args)
    plant_options = {"preset": args.preset, "noise_std_rad_s": args.noise, "seed": args.seed,
               "connect_timeout_s": args.connect_timeout}  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    job = Commission(args.plant, out, plant_options, jobs=args.jobs, run_command=run_in_process)
    code, failure = 0, None
    try:
        job.run_all()
    except StageError as exc:
        code, failure = 1, str(exc)
    except StageStoppedError as exc:
        code = 1 if exc.failure else stopping.exit_code()
        why = exc.failure or "interrupted; zero volts sent"
        if exc.failure and not exc.failure.startswith("internal error:"):  # not cartctl's own
            why = f"the cart stopped: {why}"
        failure = f"{exc.stage}: {why}"
    except KeyboardInterrupt:
        code, failure = stopping.exit_code(), f"{job.current}: interrupted; zero volts sent"
    except CartctlError as exc:  # the port or the cart in the checks (the user's to fix: its
        # own code; a cart that does not answer: 1), or a refusal further on (a stage that failed: 1)
        code, failure = (exc.exit_code if job.current == "checks" else 1), f"{job.current}: {exc}"
    except OSError as exc:  # a stage's file not written (a full disk): a fault, as in run
        code, failure = 1, f"{job.current}: {exc.strerror or exc}: {exc.filename or out}"
    if failure is not None:
        with contextlib.suppress(OSError):  # on a full disk the summary cannot be written either
            why = failure.removeprefix(f"{job.current}: ")  # the stage once, in the heading
            job.report.add("stopped", f"At stage **{job.current}**: {why}. The files written "
                           "so far are kept.")  # fmt: skip
    if args.json:
        stages = ("checks", "excitation", "model", "controller", "verification")
        print(dumps({"out": str(job.out), "plant": job.description,
                     "summary": str(job.out / "summary.md"),
                     **{stage: job.results.get(stage) for stage in stages},
                     "failed_stage": job.current if failure else None, "failure": failure,
                     "recordings": sorted(str(p) for p in job.out.glob("*.rrd")),
                     "recording_problems": job.problems}))  # fmt: skip
    elif failure is None:
        v = job.results["verification"]
        print(f"commissioned {job.description}: {job.controller_path} verified (overshoot "
              f"{v['measured']['overshoot_percent']:.1f} %, settling "
              f"{v['measured']['settling_time_s'] * 1e3:.0f} ms); see {out / 'summary.md'}")  # fmt: skip
    if failure is not None:
        print(f"cartctl commission: {failure}", file=sys.stderr)
    return code


def run_in_process(argv: list[str]) -> tuple[int, dict[str, Any] | None]:
    """``cartctl run ARGV`` in this process: its exit code and its ``--json`` summary (None when
    it printed none). Commissioning verifies its controller on the path users take."""
    import io
    import json

    from cartctl.cli.commands.run import add_parser as add_run_parser

    parser = argparse.ArgumentParser(prog="cartctl")
    add_run_parser(parser.add_subparsers())
    args = parser.parse_args(argv)
    args.say_stopped = False  # a stop signal: commission's own line names the stage
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = int(args.func(args))
    try:
        return code, json.loads(out.getvalue())
    except json.JSONDecodeError:
        return code, None
