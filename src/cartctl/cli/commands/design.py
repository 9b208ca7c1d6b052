"""``cartctl design MODEL.toml --method pi|poles``: controllers designed on identified models."""

from __future__ import annotations

import argparse
import sys
from typing import Any

import cartctl.cli.commands.options as options
from cartctl.cart import SUPPLY_V
from cartctl.design.request import (  # light: the parser's choices and defaults
    DEFAULT_BIAS_DRIFT_STD_V,
    DEFAULT_PROCESS_NOISE_STD_V,
    MAX_EXTRA_DELAY_TICKS,
    MAX_LOOP_DELAY_TICKS,
    OPTIONS,
    PI_ESTIMATORS,
    PM_RANGE_DEG,
    DesignRequest,
)
from cartctl.errors import InputError
from cartctl.runtime.base import ANTI_WINDUP  # light too (no numpy)

_DEFAULT = DesignRequest(method="pi")


def _option(group: Any, field: str, metavar: str | None, help: str, **more: Any) -> None:
    """The option of a request field (:data:`~cartctl.design.request.OPTIONS`), with the
    request's default and its type (give ``type`` where the default is None), noted in
    ``args.given`` when given (:class:`~cartctl.cli.commands.options.Given`)."""
    default = getattr(_DEFAULT, field)
    if default is not None:
        more.setdefault("type", type(default))
    group.add_argument(
        OPTIONS[field], action=options.Given, default=default, metavar=metavar, help=help, **more
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design PI or pole-placement controllers on a model",
        description="Design a discrete speed controller per motor on a model file: a PI from a "
        "phase margin and crossover (or a bandwidth), or pole placement with integral action and "
        "a Kalman speed estimator. Reports margins, the peaks of the sensitivity S and the "
        "complementary sensitivity T of the loop as it runs (estimator and loop delay included), "
        "closed-loop poles with damping and natural frequency, a simulated step with the voltage "
        "limit, the settling time against the fastest that ±12 V allows, and the rejection of a "
        "load step at the plant input.",
    )
    p.add_argument("model", metavar="MODEL.toml", help="model file, e.g. models/ground.toml")
    p.add_argument("--method", choices=("pi", "poles"), required=True)
    options.add_motor_option(p)
    pi = p.add_argument_group("PI (--method pi)")
    pm = _DEFAULT.phase_margin_deg
    _option(pi, "phase_margin_deg", "DEG", f"in (0, {PM_RANGE_DEG[1]:g}] (default {pm:g})")
    _option(pi, "crossover_hz", "F", f"default {_DEFAULT.crossover_hz:g}")
    _option(
        pi,
        "bandwidth_hz",
        "F",
        "design for this closed-loop bandwidth instead of a crossover",
        type=float,
    )
    _option(pi, "anti_windup", None, "integrator handling at the voltage limit",
            choices=ANTI_WINDUP)  # fmt: skip
    _option(pi, "estimator", None, "run the PI on a Kalman speed estimate (default: on the "
            "measurement)", choices=PI_ESTIMATORS)  # fmt: skip
    pl = p.add_argument_group("pole placement (--method poles)")
    _option(pl, "poles", "Z1,Z2,...", "closed-loop poles in the z-plane, complex as a+bj "
            "(3 for the report's model; 4 with --bias-drift-v 0, which adds an error "
            "integrator)")  # fmt: skip
    _option(pl, "settling_time_s", "S",
            "2 %% settling time for the dominant poles (default 0.06 s)")  # fmt: skip
    _option(pl, "overshoot_percent", "P",
            "overshoot for the dominant poles in %% (default 1)")  # fmt: skip
    est = p.add_argument_group("estimator")
    _option(est, "process_noise_std_v", "V", "input-equivalent process noise, std in V "
            f"(default {DEFAULT_PROCESS_NOISE_STD_V:g})")  # fmt: skip
    _option(est, "bias_drift_std_v", "V", "random-walk step per tick of the estimator's "
            "input-disturbance state (friction, model DC error), the integral action of pole "
            f"placement (default {DEFAULT_BIAS_DRIFT_STD_V:g}; 0 leaves it out)")  # fmt: skip
    _option(est, "extra_noise_std_rad_s", "RAD_S", "extra measurement noise on top of "
            "the encoder's quantisation, std in rad/s (default 0); the file's estimator records "
            "the total as measurement_noise_std_rad_s")  # fmt: skip
    _option(est, "timing_noise_std_ticks", "TICKS", "how uncertain the moment a command "
            "lands is (std in ticks): after each command change Δu the estimator adds "
            "(TICKS·Δu)²·B·Bᵀ to its process noise (default 0)")  # fmt: skip
    _option(p, "loop_delay_ticks", "N", "the loop delay the controller is for (ticks from a "
            "measurement to its voltage on the motor; default the model file's loop_delay_ticks "
            "+ extra delay, else its nk - 1 + extra delay); nk + extra delay for a model whose "
            "next measurement already sees part of a command that lands within the tick; at most "
            f"{MAX_LOOP_DELAY_TICKS}", type=int)  # fmt: skip
    _option(p, "extra_delay_ticks", "N", "ticks of loop delay beyond the model's (a PC-side "
            f"loop over serial), 0..{MAX_EXTRA_DELAY_TICKS}")  # fmt: skip
    _option(p, "voltage_limit_v", "V", "command saturation, at most 12 V (default 12)")
    _option(p, "step_rad_s", "RAD_S",
            "reference step for the simulated response (default 10 rad/s)")  # fmt: skip
    p.add_argument(
        "--disturbance-v",
        type=float,
        default=1.0,
        metavar="V",
        help="load-disturbance step added at the plant input for the simulated rejection "
        "(default 1 V)",
    )
    p.add_argument("--out", metavar="CONTROLLER.toml", help="write the controller file")
    p.add_argument(
        "--report",
        metavar="DIR",
        help="write PNGs per motor: design_X.png (Bode, step) and analysis_X.png (S and T, "
        "Nyquist, load disturbance)",
    )
    options.add_json_option(p)
    p.set_defaults(func=run)


def request_from_args(args: argparse.Namespace) -> DesignRequest:
    """The design request the options ask for (checked), field by field through
    :data:`~cartctl.design.request.OPTIONS`, so a command ``to_argv`` writes parses back to it."""
    # argparse's attribute for an option: '--phase-margin' -> phase_margin
    values = {field: getattr(args, flag[2:].replace("-", "_")) for field, flag in OPTIONS.items()}
    given = [field for field, flag in OPTIONS.items() if flag in getattr(args, "given", ())]
    return DesignRequest(method=args.method, **values).check(given=given)


def _gains_line(method: str, e: dict[str, Any]) -> str:
    from cartctl.design.loop_report import sig, sig_list

    if method == "pi":
        return f"Kp = {sig(e['kp'])} V/(rad/s), Ki = {sig(e['ki'])} V/rad"
    k = list(e["K"])
    # with the input-disturbance estimate K ends with its gain 1 (V/V) and Ki is 0: u carries −b̂
    bias = len(k) > 1 and e["Ki"] == 0.0 and abs(k[-1] - 1.0) < 1e-12
    states = k[:-1] if bias else k
    text = f"K = [{sig_list(states)}] V/(rad/s)"
    if bias:
        text += " and 1 on the disturbance estimate"
    return f"{text}, Ki = {sig(e['Ki'])} V/rad, Kr = {sig(e['Kr'])} V/(rad/s)"


def _pole_lines(e: dict[str, Any]) -> list[str]:
    from cartctl.measures.numfmt import format_column, format_fixed, render_table

    rows = e["closed_loop_pole_table"]
    inf = float("inf")
    cols = (  # z to 4 decimals: how close to the unit circle matters
        [format_fixed(r["re"], 4) for r in rows],
        [format_fixed(abs(r["im"]), 4) for r in rows],
        format_column([r["damping"] for r in rows]),
        format_column([inf if r["freq_hz"] is None else r["freq_hz"] for r in rows]),
    )
    cells = [
        (re_ + ("" if r["im"] == 0.0 else f" {'-' if r['im'] < 0 else '+'} {im}j"), zeta, f_hz)
        for r, re_, im, zeta, f_hz in zip(rows, *cols, strict=True)
    ]
    header = ("closed-loop pole z", "damping ζ", "natural frequency (Hz)")
    return render_table(header, cells, indent="  ")


def _analysis_lines(e: dict[str, Any]) -> list[str]:
    from cartctl.design.loop_report import sig
    from cartctl.measures.numfmt import format_fixed

    d = e["disturbance"]
    rec = d["recovery_time_s"]
    ms_db, mt_db = e["sensitivity_peak_db"], e["complementary_peak_db"]
    return [
        f"  sensitivity peak Ms = {sig(e['sensitivity_peak'])} ({format_fixed(ms_db, 2)} dB) at "
        f"{sig(e['sensitivity_peak_hz'])} Hz; complementary peak Mt = "
        f"{sig(e['complementary_peak'])} ({format_fixed(mt_db, 2)} dB) at "
        f"{sig(e['complementary_peak_hz'])} Hz",
        f"  {sig(d['step_v'])} V load step at the plant input: peak {sig(d['peak_deviation_rad_s'])} "
        f"rad/s at {d['peak_time_s'] * 1e3:.0f} ms, recovered (within 2 % of the peak) "
        + ("never" if rec is None else f"after {rec * 1e3:.0f} ms")
        + f", final {sig(d['final_deviation_rad_s'], scale=d['peak_deviation_rad_s'])} rad/s",
    ]


def _format(method: str, motors: dict[str, dict[str, Any]]) -> str:
    from cartctl.design.loop_report import sig

    lines = []
    for m, e in motors.items():
        step, bound = e["step"], e["settling_bound_s"]
        pm, gm, fc = e.get("phase_margin_deg"), e.get("gain_margin_db"), e.get("crossover_hz")
        settle, rise = step["settling_time_s"], step["rise_time_s"]
        lines += [
            f"motor {m}: {_gains_line(method, e)}",
            f"  margins: phase {pm:.1f}°, gain {'∞' if gm is None else f'{gm:.1f} dB'}, "
            f"crossover {fc:.2f} Hz"
            if pm is not None and fc is not None else "  margins: —",
            *_analysis_lines(e),
            *_pole_lines(e),
            f"  {step['step_rad_s']:g} rad/s step: overshoot {step['overshoot_percent']:.2f} %, "
            f"rise {'—' if rise is None else f'{rise * 1e3:.0f} ms'}, settling "
            + ("—" if settle is None else f"{settle * 1e3:.0f} ms")
            + f", peak {step['peak_voltage_v']:.2f} V, steady-state error "
            + f"{sig(step['steady_state_error'], scale=step['step_rad_s'])} rad/s",
            f"  fastest settling within the voltage limit for a loop delay of "
            f"{e['settling_bound_loop_delay_ticks']} tick(s): {bound * 1e3:.0f} ms"
            + ("" if settle is None else f" (this controller: {settle / bound:.1f}× that)"),
            "",
        ]  # fmt: skip
    return "\n".join(lines).rstrip()


def run(args: argparse.Namespace) -> int:
    request = request_from_args(args)  # every option in range before the heavy imports
    disturbance_v = options.check_finite(float(args.disturbance_v), "--disturbance-v")
    if not (disturbance_v != 0.0 and abs(disturbance_v) <= SUPPLY_V):
        raise InputError(
            f"--disturbance-v must be a non-zero voltage within ±{SUPPLY_V:g} V, "
            f"got {args.disturbance_v}"
        )
    options.check_outputs(args, files=("out",), folders=("report",), inputs=(args.model,))

    from cartctl.cli.jsonout import dumps
    from cartctl.data.modelfile import load_models
    from cartctl.design.controllerfile import save_controller
    from cartctl.design.make import check_models, controller_file, design_models, loop_delay_for

    models = load_models(args.model)
    names = ("a", "b") if args.motor == "both" else (args.motor,)
    check_models(models, names, str(args.model))
    if args.out:  # a file is for one loop: refuse before designing when there is none
        given = request.loop_delay_ticks is not None  # a misfit --loop-delay names itself
        try:
            loop_delay_for(request, {m: models.motor(m) for m in names}, models.loop_delay_ticks)
        except InputError as exc:
            raise InputError(str(exc) if given else f"--out: {exc}") from None
    try:
        designs = design_models(request, models, names, disturbance_v=disturbance_v)
    except InputError as exc:  # a refusal naming a request field names its option here
        field, _, rest = str(exc).partition(" ")
        raise InputError(f"{OPTIONS[field]} {rest}" if field in OPTIONS else str(exc)) from None
    if designs.loop_delay_note is not None:
        print(f"cartctl design: note: {designs.loop_delay_note}", file=sys.stderr)
    motors_json = designs.entries()
    for e in motors_json.values():
        for warning in e["warnings"]:
            print(f"cartctl design: warning: {warning}", file=sys.stderr)
    if args.out:
        command = options.command_line("design")
        save_controller(
            controller_file(designs, args.model, command=command, period_s=models.period_s),
            args.out,
        )
    if args.report:
        from cartctl.design.loop_report import write_report

        write_report(args.report, designs)
    if args.json:
        print(dumps({"method": args.method, "model": str(args.model), "Ts": models.period_s,
                     "loop_delay_ticks": designs.loop_delay_ticks,
                     "loop_delay_note": designs.loop_delay_note, "motors": motors_json}))  # fmt: skip
        return 0
    print(_format(args.method, motors_json))
    if args.out:
        print(f"wrote {args.out}")
    if args.report:
        print(f"wrote the report to {args.report}")
    return 0
