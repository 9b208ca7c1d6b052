"""``cartctl linearity STEP_SMALL.csv STEP_LARGE.csv STEP_SUM.csv``: the superposition test
(:mod:`cartctl.identification.validate`), ``--plot`` the report's figure 8."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import cartctl.cli.commands.options as options
from cartctl.cli.commands.validate import check_plot_path, new_figure, show

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from cartctl.identification.validate import LinearityResult


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "linearity",
        help="the superposition test: two small steps added against their sum",
        description="Check superposition on one motor (report §3.3, figure 8): align the "
        "responses to a small and a large voltage step (e.g. 3 V and 7 V) at their onsets, add "
        "them, and compare with the response to the summed step (10 V). The error is the summed "
        "step's response minus the added responses; a linear motor gives zero.",
    )
    p.add_argument("small", metavar="STEP_SMALL.csv", help="response to the small step")
    p.add_argument("large", metavar="STEP_LARGE.csv", help="response to the large step")
    p.add_argument("sum", metavar="STEP_SUM.csv", help="response to the step of their sum")
    options.add_motor_option(p, "which motor to test (default a)", "a")
    options.add_map_option(p)
    options.add_plot_option(
        p, "the added responses, the summed step's response, and the error beneath"
    )
    options.add_json_option(p, "print one JSON object instead of text")
    p.set_defaults(func=run)


def linearity_figure(result: LinearityResult) -> Figure:
    """Figure 8 of the report: the responses above, the superposition error beneath; each legend
    right of its panel, off the data."""
    small_v, large_v, sum_v = result.amplitudes_v
    fig, axes = new_figure(2, 1, width_in=10.0, height_in=6.0)
    top, bottom = axes[0, 0], axes[1, 0]
    t = result.time_s
    top.plot(t, result.speed_small_rad_s, color="0.6", lw=1.0, ls=":", label=f"{small_v:g} V step")
    top.plot(t, result.speed_large_rad_s, color="0.4", lw=1.0, ls="-.", label=f"{large_v:g} V step")
    top.plot(
        t,
        result.speed_added_rad_s,
        color="tab:blue",
        label=f"{small_v:g} V + {large_v:g} V responses added",
    )
    top.plot(t, result.speed_sum_rad_s, color="tab:orange", ls="--", label=f"{sum_v:g} V step")
    top.set_ylabel("speed (rad/s)")
    top.set_title(f"motor {result.motor}: responses aligned at their step onsets")
    top.legend(**_BESIDE)
    bottom.plot(t, result.error_rad_s, color="tab:red", label="error (sum step − added)")
    bottom.axhline(0.0, color="0.3", lw=0.8)
    bottom.axhline(
        result.mean_error_rad_s,
        color="tab:red",
        ls="--",
        lw=0.8,
        label=f"mean {result.mean_error_rad_s:+.3f} rad/s",
    )
    bottom.set_ylabel("error (rad/s)")
    bottom.set_xlabel("time since the step (s)")
    bottom.legend(**_BESIDE)
    fig.suptitle("Superposition test")
    return fig


# legends outside the axes, to their right (constrained layout makes room)
_BESIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0}


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{value:+.2f} %"


def format_text(result: LinearityResult, files: tuple[str, str, str]) -> str:
    small_v, large_v, sum_v = result.amplitudes_v
    lines = [f"superposition test, motor {result.motor}"]
    for role, path, amp, onset in zip(
        ("small", "large", "sum"), files, result.amplitudes_v, result.onsets_s, strict=True
    ):
        lines.append(f"  {role:<6} {amp:>7.3g} V step at {onset:6.2f} s   {path}")
    lines += [
        "",
        f"  error = {sum_v:g} V response − ({small_v:g} V + {large_v:g} V responses), "
        f"over {result.time_s[-1]:.2f} s after the onsets",
        f"  {'mean':<8} {result.mean_error_rad_s:+9.3f} rad/s   "
        f"{_pct(result.mean_error_percent)} of the {sum_v:g} V steady state "
        f"({result.steady_state_sum_rad_s:.3f} rad/s)",
        f"  {'max |e|':<8} {result.max_abs_error_rad_s:9.3f} rad/s",
        f"  {'rms':<8} {result.rms_error_rad_s:9.3f} rad/s   "
        f"{_pct(result.rms_error_percent).lstrip('+')} of the {sum_v:g} V response's rms",
    ]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from cartctl.data.read import read_trace
    from cartctl.identification.validate import linearity

    check_plot_path(args.plot)
    files = (args.small, args.large, args.sum)
    small, large, total = (read_trace(path, args.map) for path in files)
    result = linearity(small, large, total, args.motor)
    return show(
        args, result.to_dict(), format_text(result, files), lambda: linearity_figure(result)
    )
