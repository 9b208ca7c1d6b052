"""``cartctl validate MODEL.toml FILE.csv``: a model simulated on recorded input against the
measured speed (:mod:`cartctl.identification.validate`), ``--plot`` the report's figures 6 and 7.
Also the ``--plot`` helpers ``cartctl linearity`` shares."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cartctl.cli.commands.options as options
from cartctl.errors import InputError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from cartctl.identification.validate import ModelValidation, ValidationResult


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="simulate a model on recorded data against the measured speed",
        description="Simulate each motor's model from rest on the trace's commanded voltage and "
        "compare with the measured speed: the simulation fit (%), the absolute error over time "
        "and, when the input is a single step, rise time, overshoot, settling time and steady "
        "state of the measured and simulated responses side by side (report §3.3).",
    )
    p.add_argument("model", metavar="MODEL.toml", help="model file, e.g. models/ground.toml")
    p.add_argument("data", metavar="FILE.csv", help="recorded experiment (CSV or QRC log)")
    options.add_motor_option(
        p, "which motor to validate (default both; a motor left at 0 V is then skipped)"
    )
    options.add_map_option(p)
    options.add_plot_option(p, "measured and simulated speed with the absolute error beneath")
    options.add_json_option(p, "print one JSON object instead of a table")
    p.set_defaults(func=run)


def check_plot_path(path: str | None) -> Path | None:
    """The ``--plot`` path, refused before any work unless it names a writable .png file."""
    if path is None:
        return None
    out = Path(path)
    if out.suffix.lower() != ".png":
        raise InputError(f"--plot writes a PNG image; give a file ending in .png, got {path!r}")
    return options.check_output_file(out, "--plot")


def new_figure(rows: int, cols: int, *, width_in: float, height_in: float) -> tuple[Figure, Any]:
    """A matplotlib figure on the Agg canvas (no GUI, no pyplot state) and its grid of axes, each
    with a light grid."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(
        rows, cols, sharex="col", squeeze=False, height_ratios=[2] + [1] * (rows - 1)
    )
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
    return fig, axes


def show(args: argparse.Namespace, doc: dict[str, Any], text: str, figure: Any) -> int:
    """``figure()`` saved to ``--plot`` (if given), then ``doc`` as JSON or ``text`` and where the
    figure went (validate's and linearity's output)."""
    from cartctl.cli.jsonout import dumps
    from cartctl.data.outputs import writing

    path = None if args.plot is None else Path(args.plot)
    if path is not None:
        with writing(path):
            figure().savefig(path, format="png", dpi=120)
    print(dumps(doc) if args.json else text)
    if path is not None and not args.json:
        print(f"\nwrote {path}")
    return 0


def validation_figure(validation: ModelValidation) -> Figure:
    """Figures 6 and 7 of the report in one PNG: per motor, speeds above and |error| beneath."""
    results = list(validation.results.values())
    fig, axes = new_figure(2, len(results), width_in=6.0 * len(results), height_in=6.0)
    for col, r in enumerate(results):
        top, bottom = axes[0, col], axes[1, col]
        top.plot(r.time_s, r.measured_rad_s, label="measured", color="tab:blue")
        top.plot(r.time_s, r.simulated_rad_s, label="simulated", color="tab:orange", ls="--")
        top.set_title(f"motor {r.motor}: fit {r.fit_simulation_percent:.1f} % (simulation)")
        top.set_ylabel("speed (rad/s)")
        top.legend(loc="best")
        bottom.plot(r.time_s, r.abs_error_rad_s, color="tab:red", label="|measured − simulated|")
        bottom.set_ylabel("|error| (rad/s)")
        bottom.set_xlabel("time (s)")
        bottom.legend(loc="best")
    model = Path(validation.model).name if validation.model else "model"
    data = Path(validation.data).name if validation.data else "trace"
    fig.suptitle(f"Validation of {model} on {data}")
    return fig


def _num(value: float | None, spec: str) -> str:
    return "—" if value is None else format(value, spec)


_STEP_ROWS = (  # label, StepInfo field, format
    ("rise time 10–90 % (s)", "rise_time_s", ".3f"),
    ("overshoot (%)", "overshoot_percent", ".1f"),
    ("settling time (s)", "settling_time_s", ".3f"),
    ("peak (rad/s)", "peak_value", ".3f"),
    ("steady state (rad/s)", "steady_state_value", ".3f"),
)


def format_result(r: ValidationResult) -> list[str]:
    if r.unstable_pole is not None:
        return [
            f"motor {r.motor}: the model is {r.stability} (pole at |z| = {r.unstable_pole:.4g}): "
            "its simulation runs away or drifts, so there is no fit to show"
        ]
    e = r.error_summary()
    lines = [
        f"motor {r.motor}: fit {_num(r.fit_simulation_percent, '.2f')} % (simulation)",
        f"  |error| (rad/s): max {e['max']:.3f}, mean {e['mean']:.3f}, rms {e['rms']:.3f}",
    ]
    if r.step is None:
        lines.append("  input is not a single step from 0 V: no step metrics")
        return lines
    s = r.step
    lines.append(
        f"  {f'step of {s.amplitude_v:g} V at {s.onset_s:.2f} s':<26} {'measured':>10} "
        f"{'simulated':>10}"
    )
    for label, key, spec in _STEP_ROWS:
        m, sim = (_num(getattr(info, key), spec) for info in (s.measured, s.simulated))
        lines.append(f"  {label:<26} {m:>10} {sim:>10}")
    lines.append(
        f"  steady-state error of the model (measured − simulated): "
        f"{s.steady_state_error_rad_s:+.3f} rad/s"
    )
    return lines


def format_table(validation: ModelValidation) -> str:
    lines = [
        f"validate {validation.model} on {validation.data} (Ts = {validation.period_s * 1e3:g} ms)"
    ]
    for r in validation.results.values():
        lines += ["", *format_result(r)]
    if any(r.step is not None for r in validation.results.values()):
        from cartctl.cart import encoder_quantum_rad_s

        q = encoder_quantum_rad_s(validation.period_s)
        lines += [
            "",
            f"settling band: max(2 % of the step, one encoder count per tick = {q:.3g} rad/s)",
        ]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from cartctl.data.modelfile import load_models
    from cartctl.data.read import read_trace
    from cartctl.data.trace import MOTORS
    from cartctl.identification.validate import validate_models

    def say(line: str) -> None:
        print(f"cartctl validate: {line}", file=sys.stderr)

    check_plot_path(args.plot)
    models = load_models(args.model)
    trace = read_trace(args.data, args.map)
    motors: tuple[str, ...] = (args.motor,)
    if args.motor == "both":
        motors = tuple(m for m in MOTORS if m in models.motors)
        for name in sorted(set(MOTORS) - set(motors)):
            say(f"note: {args.model} has no model of motor {name}; skipped")
    validation = validate_models(models, trace, motors, skip_idle=args.motor == "both")
    for name in validation.skipped:
        say(f"note: motor {name}'s voltage is zero throughout {args.data}; skipped")
    for r in validation.results.values():
        if r.unstable_pole is not None:
            say(
                f"warning: {args.model}: motor {r.motor}'s model is {r.stability} (pole at |z| = "
                f"{r.unstable_pole:.4g}); identify it again"
            )
    text = format_table(validation)
    return show(args, validation.to_dict(), text, lambda: validation_figure(validation))
