"""``cartctl inspect MODEL.toml [--json]``: poles, zeros, continuous-equivalent frequencies, DC gain."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING, Any

import cartctl.cli.commands.options as options
from cartctl.measures.numfmt import format_fixed, render_table

if TYPE_CHECKING:
    from cartctl.data.modelfile import ModelFile
    from cartctl.model import ArxModel, Root


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "inspect",
        help="poles, zeros, continuous-equivalent frequencies and DC gain of a model file",
        description="Show each motor's transfer function, its poles and zeros with their "
        "continuous-equivalent frequencies f = |ln z| / (2π Ts) and damping, and its DC gain. A "
        "pole at z = 0 is a pure delay and has no frequency. Zeros outside the unit circle (|z| > "
        "1) are flagged: such a model is not minimum phase, and a controller must not cancel "
        "those zeros.",
    )
    p.add_argument("model", metavar="MODEL.toml", help="model file, e.g. models/ground.toml")
    options.add_json_option(
        p, "print one JSON object (keys: docs/architecture.md) instead of a table"
    )
    p.set_defaults(func=run)


def _slow(root: Root) -> bool:
    """A stable pole with |z| above :data:`~cartctl.model.MARGINAL_POLE_RADIUS` (slow or
    marginal); one on the unit circle or outside it is not stable."""
    from cartctl.model import MARGINAL_POLE_RADIUS, UNIT_CIRCLE_TOLERANCE

    return MARGINAL_POLE_RADIUS < abs(root.value) < 1.0 - UNIT_CIRCLE_TOLERANCE


def outside_zeros(model: ArxModel) -> list[complex]:
    """The zeros with |z| > 1 (non-minimum-phase)."""
    return [r.value for r in model.zeros() if abs(r.value) > 1.0]


def model_summary(model: ArxModel) -> dict[str, Any]:
    """``inspect --json``'s entry of one motor."""
    from cartctl.measures.metrics import finite_or_none

    marginal = model.is_stable() and any(_slow(r) for r in model.poles())
    outside = bool(outside_zeros(model))
    return {
        "minimum_phase": not outside,
        "slow_or_marginal": marginal,
        "flags": ["slow_or_marginal"] * marginal + ["non_minimum_phase"] * outside,
        "poles": [
            r.to_dict() | {"magnitude": abs(r.value), "slow_or_marginal": _slow(r)}
            for r in model.poles()
        ],
        "zeros": [r.to_dict() for r in model.zeros()],
        "dc_gain": finite_or_none(model.dc_gain()),
        "stable": model.is_stable(),
        "nk": model.nk,
        "num": model.num().tolist(),
        "den": model.den().tolist(),
    }


def _fmt_z(z: complex) -> str:
    if z.imag == 0.0:
        return f"{z.real:.4f}"
    return f"{z.real:.4f} {'+' if z.imag > 0 else '−'} {abs(z.imag):.4f}j"


def _cells(root: Root) -> list[str]:
    from cartctl.model import UNIT_CIRCLE_TOLERANCE

    flag = "non-minimum-phase" if root.kind == "zero" and abs(root.value) > 1.0 else ""
    if root.kind == "pole" and _slow(root):
        flag = "slow or marginal (|z| > 0.99)"
    elif root.kind == "pole" and abs(abs(root.value) - 1.0) <= UNIT_CIRCLE_TOLERANCE:
        flag = "on the unit circle"
    elif root.kind == "pole" and abs(root.value) > 1.0:
        flag = "unstable (|z| > 1)"
    z, freq, damping = root.value, format_fixed(root.freq_hz, 2), format_fixed(root.damping, 3)
    return [root.kind, _fmt_z(z), f"{abs(z):.4f}", freq, damping, flag]


def format_table(models: ModelFile) -> str:
    prov = models.provenance
    lines = [
        f"{models.path}",
        f"  {prov.source}",
        f"  method {prov.method}, prefilter {prov.prefilter}, created {prov.created}; Ts = {models.period_s * 1e3:g} ms",
    ]
    for name, m in models.motors.items():
        gain = m.dc_gain()
        lines += [
            "",
            f"  motor {name}:  H(z) = {m.describe()}    (input delay nk = {m.nk})",
        ]
        cells = [_cells(r) for r in (*m.poles(), *m.zeros())]
        headers = ["kind", "z (–)", "|z| (–)", "f (Hz)", "ζ (–)", ""]
        lines += render_table(headers, cells, left=(0, 5), indent="    ")
        gain_txt = f"{gain:.4g} rad/s/V" if math.isfinite(gain) else "unbounded (integrator)"
        outside = outside_zeros(m)
        phase = "minimum phase"
        if outside:
            where = ", ".join(f"z = {_fmt_z(z)}" for z in outside)
            phase = (
                f"NOT minimum phase: zero{'s' if len(outside) > 1 else ''} outside the unit "
                f"circle at {where} (a controller must not cancel {'them' if len(outside) > 1 else 'it'})"
            )
        kind = m.stability()  # marginally: simple poles on the unit circle, none outside
        stability = kind if kind == "stable" else kind.upper()
        marginal = [abs(r.value) for r in m.poles() if _slow(r)]
        if marginal and m.is_stable():
            radius = max(marginal)
            stability += (
                f" but SLOW OR MARGINAL: a pole at |z| = {radius:.4f} > 0.99 (it decays by "
                f"{100.0 * (1.0 - radius):.2g} % a tick)"
            )
        lines.append(f"    DC gain {gain_txt}, {stability}, {phase}")
    lines.append("")
    lines.append(
        "  f = |ln z| / (2π Ts); a delay pole (z = 0) has no frequency; ζ is the damping ratio; "
        "a zero with |z| > 1 is non-minimum-phase; a pole with |z| > 0.99 is slow or marginal, "
        "simple poles on the unit circle are marginally stable."
    )
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from cartctl.cli.jsonout import dumps
    from cartctl.data.modelfile import load_models

    models = load_models(args.model)
    if args.json:
        motors = {n: model_summary(m) for n, m in models.motors.items()}
        print(dumps({"Ts": models.period_s, "motors": motors}))
    else:
        print(format_table(models))
    return 0
