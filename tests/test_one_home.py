"""Each fact of the cart, and each shared table, has one home in ``src/cartctl``.

Read from the source with :mod:`ast` (nothing is imported): the cart's period, supply and encoder
live in ``cartctl/cart.py`` and are imported from there, never copied under another name, never
written as a literal default; the voltage-limit rule, the encoder quantum, the anti-windup modes,
the trace columns and the Rerun entity paths are each written once.
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "cartctl"
CART = "cart.py"
CART_NAMES = {"SUPPLY_V", "PERIOD_S", "ENCODER_COUNTS_PER_REV", "PWM_STEP_V"}
OLD_ALIASES = {"MAX_VOLTAGE_V", "TS_S", "CART_PERIOD_S", "SPEED_QUANTUM_RAD_S", "COUNTS_PER_REV"}


@cache
def _trees() -> dict[str, ast.Module]:
    """Every module of the package (generated code aside), by path relative to the package."""
    return {
        p.relative_to(PACKAGE).as_posix(): ast.parse(p.read_text(encoding="utf-8"))
        for p in sorted(PACKAGE.rglob("*.py"))
        if "vendor" not in p.parts
    }


def _assigned(node: ast.AST) -> list[str]:
    targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
    return [t.id for t in targets if isinstance(t, ast.Name)]


def test_the_package_is_read() -> None:
    assert CART in _trees() and len(_trees()) > 50


def test_cart_names_are_assigned_in_cart_py_only() -> None:
    wrong = []
    for path, tree in _trees().items():
        for node in ast.walk(tree):
            if isinstance(node, ast.Assign | ast.AnnAssign):
                for name in _assigned(node):
                    if name in OLD_ALIASES or (name in CART_NAMES and path != CART):
                        wrong.append(f"{path}:{node.lineno} assigns {name}")
    assert wrong == []


def test_no_alias_of_a_cart_name() -> None:
    """Neither ``from cartctl.cart import PERIOD_S as TS_S`` nor ``TS_S = PERIOD_S``."""
    wrong = []
    for path, tree in _trees().items():
        from_cart: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module == "cartctl.cart":
                for alias in node.names:
                    from_cart.add(alias.asname or alias.name)
                    if alias.asname is not None:
                        wrong.append(f"{path}:{node.lineno} imports {alias.name} as {alias.asname}")
        for node in tree.body:  # module level: NAME = <a name imported from cartctl.cart>
            if (
                isinstance(node, ast.Assign | ast.AnnAssign)
                and isinstance(node.value, ast.Name)
                and node.value.id in from_cart
            ):
                wrong.append(f"{path}:{node.lineno} copies {node.value.id}")
    assert wrong == []


def _defaults(tree: ast.Module) -> list[tuple[str, ast.expr, int]]:
    """(name, default) of every parameter and every class-level annotated field."""
    out: list[tuple[str, ast.expr, int]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            a = node.args
            positional = [*a.posonlyargs, *a.args]
            pairs = list(
                zip(positional[len(positional) - len(a.defaults) :], a.defaults, strict=True)
            )
            pairs += [(arg, d) for arg, d in zip(a.kwonlyargs, a.kw_defaults, strict=True) if d]
            out += [(arg.arg, d, node.lineno) for arg, d in pairs]
        elif isinstance(node, ast.ClassDef):
            out += [
                (n.target.id, n.value, n.lineno)
                for n in node.body
                if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name) and n.value
            ]
    return out


def test_no_literal_period_or_supply_default() -> None:
    """``period_s: float = 0.01`` and ``voltage_limit_v: float = 12.0`` are the cart's
    ``PERIOD_S`` and ``SUPPLY_V``, by name."""
    wrong = []
    for path, tree in _trees().items():
        for name, default, line in _defaults(tree):
            if not isinstance(default, ast.Constant) or isinstance(default.value, bool):
                continue
            value = default.value
            if "period" in name and value == 0.01:
                wrong.append(f"{path}:{line} {name} = {value}")
            if re.search("volt|supply|limit_v", name) and value == 12:
                wrong.append(f"{path}:{line} {name} = {value}")
    assert wrong == []


def test_one_voltage_limit_check() -> None:
    """The rule 0 < limit <= supply is written in cartctl.cart.check_voltage_limit alone."""
    wrong = []
    for path, tree in _trees().items():
        if path == CART:
            continue
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Compare)
                and any(isinstance(op, ast.LtE) for op in node.ops)
                and isinstance(node.comparators[-1], ast.Name)
                and node.comparators[-1].id == "SUPPLY_V"
                and isinstance(node.ops[0], ast.Lt)
            ):
                wrong.append(f"{path}:{node.lineno}")
            if isinstance(node, ast.Constant) and "limit must be in (0" in str(node.value):
                wrong.append(f"{path}:{node.lineno} words the rule itself")
    assert wrong == []


def test_once_defined() -> None:
    """The encoder quantum, the anti-windup modes and the settling half-width: one definition."""
    homes: dict[str, list[str]] = {}
    for path, tree in _trees().items():
        for node in ast.walk(tree):
            names = _assigned(node) if isinstance(node, ast.Assign | ast.AnnAssign) else []
            if isinstance(node, ast.FunctionDef):
                names = [node.name]
            for name in names:
                if name in {"encoder_quantum_rad_s", "ANTI_WINDUP", "settling_half_width"}:
                    homes.setdefault(name, []).append(path)
    assert homes == {
        "encoder_quantum_rad_s": [CART],
        "ANTI_WINDUP": ["runtime/base.py"],
        "settling_half_width": ["measures/stepinfo.py"],
    }


def _strings(path: str) -> list[str]:
    return [
        n.value
        for n in ast.walk(_trees()[path])
        if isinstance(n, ast.Constant) and isinstance(n.value, str)
    ]


def test_trace_columns_and_entity_paths_written_once() -> None:
    """The closed-loop columns start from the trace columns (not a copy of them), and no entity path
    is spelled out twice among the sinks."""
    required = {"time_s", "voltage_a", "voltage_b", "speed_a", "speed_b"}
    assert required <= set(_strings("data/trace.py"))
    assert not required & set(_strings("sinks/base.py"))
    spelled = [
        s
        for path in _trees()
        if path.startswith("sinks/")
        for s in _strings(path)
        if re.fullmatch(r"(motor/[ab]|loop)/\w+", s)
    ]
    assert len(spelled) == len(set(spelled)), sorted(spelled)


def test_the_public_ts_s_is_the_carts_period() -> None:
    import cartctl
    from cartctl.cart import PERIOD_S

    assert "TS_S" in cartctl.__all__ and cartctl.TS_S is PERIOD_S
