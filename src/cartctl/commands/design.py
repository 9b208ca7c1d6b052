"""``cartctl design MODEL.toml --method pi|poles``: controllers designed on identified models."""

from __future__ import annotations

import argparse
import math
import shlex
import sys
from datetime import UTC, datetime
from typing import Any

from cartctl.design.analysis import StepAnalysis, simulate_step
from cartctl.design.build import ESTIMATOR_GAINS, make_estimator, pi_entry, poles_entry
from cartctl.design.controllerfile import (
    ControllerFile,
    common_loop_delay,
    file_sha256,
    save_controller,
)
from cartctl.design.kalman import (
    DEFAULT_BIAS_DRIFT_STD_V,
    DEFAULT_PROCESS_NOISE_STD_V,
    design_kalman,
)
from cartctl.design.limit import in_settling_band, settling_bound
from cartctl.design.loop import feedback_tf_coeffs, loop_analysis
from cartctl.design.pi import design_pi, design_pi_bandwidth
from cartctl.design.poles import design_poles
from cartctl.errors import InputError
from cartctl.jsonout import dumps
from cartctl.model import ArxModel
from cartctl.modelfile import load_models
from cartctl.runtime.base import Controller
from cartctl.runtime.pi import PiController
from cartctl.runtime.statefeedback import StateFeedbackController


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design PI or pole-placement controllers on a model",
        description=(
            "Design a discrete speed controller per motor on a model file: a PI from a phase margin "
            "and crossover (or a bandwidth), or pole placement with integral action and a Kalman "
            "speed estimator. Reports margins, closed-loop poles, a simulated step with the "
            "voltage limit, and the settling time against the fastest that ±12 V allows."
        ),
    )
    p.add_argument("model", metavar="MODEL.toml", help="model file, e.g. models/ground.toml")
    p.add_argument("--method", choices=("pi", "poles"), required=True)
    p.add_argument("--motor", choices=("a", "b", "both"), default="both", help="default both")
    pi = p.add_argument_group("PI (--method pi)")
    pi.add_argument("--phase-margin", type=float, default=65.0, metavar="DEG", help="default 65")
    pi.add_argument("--crossover-hz", type=float, default=3.0, metavar="F", help="default 3")
    pi.add_argument(
        "--bandwidth-hz",
        type=float,
        metavar="F",
        help="design for this closed-loop bandwidth instead of a crossover",
    )
    pi.add_argument(
        "--anti-windup",
        choices=("conditional", "back-calculation", "none"),
        default="conditional",
        help="integrator handling at the voltage limit",
    )
    pi.add_argument(
        "--estimator",
        choices=("none", "kalman"),
        default="none",
        help="run the PI on a Kalman speed estimate (default: on the measurement)",
    )
    pl = p.add_argument_group("pole placement (--method poles)")
    pl.add_argument(
        "--poles",
        metavar="Z1,Z2,...",
        help="closed-loop poles in the z-plane, complex as a+bj (3 for the report's model; 4 with "
        "--bias-drift-v 0, which adds an error integrator)",
    )
    pl.add_argument(
        "--settling-time",
        type=float,
        default=0.06,
        metavar="S",
        help="2 %% settling time for the dominant poles (default 0.06 s)",
    )
    pl.add_argument(
        "--overshoot",
        type=float,
        default=1.0,
        metavar="P",
        help="overshoot for the dominant poles in %% (default 1)",
    )
    est = p.add_argument_group("estimator")
    est.add_argument(
        "--estimator-gain",
        choices=ESTIMATOR_GAINS,
        default="kalman",
        help="kalman: filterpy's filter (time-varying gain); steady-state: fixed gain",
    )
    est.add_argument(
        "--process-noise-v",
        type=float,
        default=DEFAULT_PROCESS_NOISE_STD_V,
        metavar="V",
        help=f"input-equivalent process noise, std in V (default {DEFAULT_PROCESS_NOISE_STD_V:g})",
    )
    est.add_argument(
        "--bias-drift-v",
        type=float,
        default=DEFAULT_BIAS_DRIFT_STD_V,
        metavar="V",
        help="random-walk step per tick of the estimator's input-disturbance state (friction, "
        f"model DC error), the integral action of pole placement (default "
        f"{DEFAULT_BIAS_DRIFT_STD_V:g}; 0 leaves it out)",
    )
    est.add_argument(
        "--measurement-noise",
        type=float,
        default=0.0,
        metavar="RAD_S",
        help="measurement noise beyond encoder quantisation, std in rad/s (default 0)",
    )
    p.add_argument(
        "--extra-delay",
        type=int,
        default=0,
        metavar="N",
        help="ticks of loop delay beyond the model's (a PC-side loop over serial)",
    )
    p.add_argument(
        "--voltage-limit",
        type=float,
        default=12.0,
        metavar="V",
        help="command saturation, at most 12 V (default 12)",
    )
    p.add_argument(
        "--step",
        type=float,
        default=10.0,
        metavar="RAD_S",
        help="reference step for the simulated response (default 10 rad/s)",
    )
    p.add_argument("--out", metavar="CONTROLLER.toml", help="write the controller file")
    p.add_argument("--report", metavar="DIR", help="write Bode and step PNGs")
    p.add_argument("--json", action="store_true", help="print one JSON object (contract 3)")
    p.set_defaults(func=run)


def parse_poles(text: str) -> list[complex]:
    """'0.8,0.7+0.1j,0.7-0.1j' → complex numbers; a clear error otherwise."""
    out = []
    for item in text.split(","):
        try:
            out.append(complex(item.strip().replace(" ", "")))
        except ValueError:
            raise InputError(
                f"--poles: '{item.strip()}' is not a number; write poles like 0.8 or 0.7+0.1j"
            ) from None
    return out


def _check(args: argparse.Namespace) -> None:
    if not 0.0 < args.voltage_limit <= 12.0:
        raise InputError(f"--voltage-limit must be in (0, 12] V, got {args.voltage_limit}")
    if args.extra_delay < 0:
        raise InputError(f"--extra-delay must be >= 0 ticks, got {args.extra_delay}")
    if not (math.isfinite(args.step) and args.step != 0.0):
        raise InputError(f"--step must be a non-zero speed in rad/s, got {args.step}")


def _design_motor(
    args: argparse.Namespace, model: ArxModel
) -> tuple[Controller, dict[str, Any], dict[str, Any]]:
    """(runtime controller, JSON entry, controller-file entry) of one motor."""
    extra = args.extra_delay
    if args.method == "pi":
        if args.bandwidth_hz is not None:
            d = design_pi_bandwidth(
                model,
                bandwidth_hz=args.bandwidth_hz,
                phase_margin_deg=args.phase_margin,
                extra_delay_ticks=extra,
            )
        else:
            d = design_pi(model, phase_margin_deg=args.phase_margin, crossover_hz=args.crossover_hz,
                          extra_delay_ticks=extra)  # fmt: skip
        kalman = None
        if args.estimator == "kalman":
            kalman = design_kalman(model, process_noise_std_v=args.process_noise_v,
                                   bias_drift_std_v=args.bias_drift_v,
                                   extra_noise_std_rad_s=args.measurement_noise,
                                   extra_delay_ticks=extra)  # fmt: skip
        ctrl = PiController(d.kp, d.ki, model.period_s, voltage_limit_v=args.voltage_limit,
                            anti_windup=args.anti_windup,
                            estimator=None if kalman is None else make_estimator(kalman, args.estimator_gain))  # fmt: skip
        entry = {**d.to_dict(), **d.analysis()}
        if kalman is not None:
            entry["estimator_poles"] = [[p.real, p.imag] for p in kalman.poles()]
        return ctrl, entry, pi_entry(d, args.anti_windup, kalman)
    poles = parse_poles(args.poles) if args.poles else None
    d = design_poles(
        model,
        poles=poles,
        settling_time_s=None if poles else args.settling_time,
        overshoot_percent=None if poles else args.overshoot,
        extra_delay_ticks=extra,
        process_noise_std_v=args.process_noise_v,
        bias_drift_std_v=args.bias_drift_v,
        extra_noise_std_rad_s=args.measurement_noise,
    )
    ctrl = StateFeedbackController(d, estimator=make_estimator(d.estimator, args.estimator_gain),
                                   voltage_limit_v=args.voltage_limit)  # fmt: skip
    num, den = feedback_tf_coeffs(d)
    loop = loop_analysis(num, den, model, extra)
    entry = {
        **{k: v for k, v in d.to_dict().items() if k != "estimator"},
        "phase_margin_deg": loop["phase_margin_deg"],
        "gain_margin_db": loop["gain_margin_db"],
        "crossover_hz": loop["crossover_hz"],
        "sensitivity_peak": loop["sensitivity_peak"],
        "sensitivity_peak_db": loop["sensitivity_peak_db"],
        "controller_num": num.tolist(),
        "controller_den": den.tolist(),
    }
    return ctrl, entry, poles_entry(d, num, den)


def _request(args: argparse.Namespace) -> dict[str, Any]:
    req: dict[str, Any] = {"extra_delay_ticks": args.extra_delay, "step_rad_s": args.step,
                           "estimator_gain": args.estimator_gain,
                           "process_noise_std_v": args.process_noise_v,
                           "bias_drift_std_v": args.bias_drift_v,
                           "measurement_noise_std_rad_s": args.measurement_noise}  # fmt: skip
    if args.method == "pi":
        req.update(phase_margin_deg=args.phase_margin, anti_windup=args.anti_windup,
                   estimator=args.estimator)  # fmt: skip
        if args.bandwidth_hz is not None:
            req["bandwidth_hz"] = args.bandwidth_hz
        else:
            req["crossover_hz"] = args.crossover_hz
    elif args.poles:
        req["poles"] = args.poles
    else:
        req.update(settling_time_s=args.settling_time, overshoot_percent=args.overshoot)
    return req


def _format(method: str, motors: dict[str, dict[str, Any]]) -> str:
    lines = []
    for m, e in motors.items():
        step, bound = e["step"], e["settling_bound_s"]
        if method == "pi":
            gains = f"Kp = {e['kp']:.4g} V/(rad/s), Ki = {e['ki']:.4g} V/rad"
        else:
            gains = f"K = [{', '.join(f'{v:.4g}' for v in e['K'])}], Ki = {e['Ki']:.4g}, Kr = {e['Kr']:.4g}"
        pm, gm, fc = e.get("phase_margin_deg"), e.get("gain_margin_db"), e.get("crossover_hz")
        settle = step["settling_time_s"]
        lines += [
            f"motor {m}: {gains}",
            f"  margins: phase {pm:.1f}°, gain {'∞' if gm is None else f'{gm:.1f} dB'}, "
            f"crossover {fc:.2f} Hz, sensitivity peak {e['sensitivity_peak']:.2f}"
            if pm is not None and fc is not None else "  margins: —",
            "  closed-loop poles: " + ", ".join(
                f"{complex(*p):.4f}".strip("()") for p in e["closed_loop_poles"]),
            f"  {step['step_rad_s']:g} rad/s step: overshoot {step['overshoot_percent']:.2f} %, "
            f"rise {step['rise_time_s'] * 1e3:.0f} ms, settling "
            + ("—" if settle is None else f"{settle * 1e3:.0f} ms")
            + f", peak {step['peak_voltage_v']:.2f} V, steady-state error {step['steady_state_error']:.2g} rad/s",
            f"  fastest settling within the voltage limit for a loop delay of "
            f"{e['settling_bound_loop_delay_ticks']} tick(s): {bound * 1e3:.0f} ms"
            + ("" if settle is None else f" (this controller: {settle / bound:.1f}× that)"),
            "",
        ]  # fmt: skip
    return "\n".join(lines).rstrip()


def run(args: argparse.Namespace) -> int:
    _check(args)
    models = load_models(args.model)
    names = ("a", "b") if args.motor == "both" else (args.motor,)
    loop_delay = None
    if args.out:  # a file is for one loop: refuse before designing when the motors' nk differ
        try:
            loop_delay = common_loop_delay({m: models.motor(m).nk for m in names}, args.extra_delay)
        except ValueError as exc:
            raise InputError(f"--out: {exc}") from None
    motors_json: dict[str, dict[str, Any]] = {}
    motors_file: dict[str, dict[str, Any]] = {}
    steps: dict[str, StepAnalysis] = {}
    for m in names:
        model = models.motor(m)
        ctrl, entry, file_entry = _design_motor(args, model)
        step = simulate_step(ctrl, model, step_rad_s=args.step, extra_delay_ticks=args.extra_delay)
        bound = settling_bound(model, args.step, voltage_limit_v=args.voltage_limit,
                               extra_delay_ticks=args.extra_delay)  # fmt: skip
        step = in_settling_band(step, model.period_s)  # the bound's band: max(2 %, one count)
        settle = step.info.settling_time_s
        entry["step"] = step.to_dict()
        entry["settling_bound_s"] = bound.settling_time_s
        entry["settling_ratio"] = None if settle is None else settle / bound.settling_time_s
        entry["settling_bound_loop_delay_ticks"] = bound.loop_delay_ticks
        motors_json[m] = entry
        motors_file[m] = {**file_entry, "analysis": {k: v for k, v in entry.items()
                                                     if k in ("phase_margin_deg", "gain_margin_db", "crossover_hz", "sensitivity_peak",
                                                              "closed_loop_poles", "estimator_poles", "step",
                                                              "settling_bound_s", "settling_ratio",
                                                              "settling_bound_loop_delay_ticks")}}  # fmt: skip
        steps[m] = step
    if args.out:
        command = "cartctl " + shlex.join(sys.argv[1:]) if sys.argv[1:] else "cartctl design"
        save_controller(
            ControllerFile(
                method=args.method, period_s=models.period_s, voltage_limit_v=args.voltage_limit,
                model_path=str(args.model), model_sha256=file_sha256(args.model),
                request=_request(args), motors=motors_file,
                created=datetime.now(UTC).isoformat(timespec="seconds"), command=command,
                loop_delay_ticks=loop_delay,
            ),
            args.out,
        )  # fmt: skip
    if args.report:
        from cartctl.design.plots import write_design_report

        write_design_report(args.report, args.method, {m: models.motor(m) for m in names}, motors_json, steps,
                            extra_delay_ticks=args.extra_delay, voltage_limit_v=args.voltage_limit)  # fmt: skip
    if args.json:
        print(dumps({"method": args.method, "model": str(args.model), "Ts": models.period_s,
                          "motors": motors_json}))  # fmt: skip
        return 0
    print(_format(args.method, motors_json))
    if args.out:
        print(f"wrote {args.out}")
    if args.report:
        print(f"wrote the report to {args.report}")
    return 0
