"""The import graph of ``src/cartctl``: one-way layers, no circles, a short package root.

Layers, from the bottom: the core (the cart's facts, errors, the model, the reference and
excitation signals, the files and formats in ``data/``, the figures of merit in ``measures/``),
then what runs (runtime, plants, sinks, and ``link/``: the serial link and the cart's emulation),
then what makes things (identification, design, tune, export), then the Python API, the
commands (``cli/commands/`` and their helpers ``cli/jsonout``, ``cli/progress``) and
commissioning (which runs ``cartctl run``'s command in process, to verify on the path users
take), then the command line itself (``cartctl.cli``). A module imports from its own layer or
below, with two more rules: runtime consumes plain data and imports nothing from design, and
nothing imports the command line (``cartctl.cli``) but ``__main__``. Function-level imports
count as much as top-level ones.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
CORE = {"cartctl", "cart", "choices", "errors", "model", "reference", "signals", "stopping",
        "data", "measures"}  # fmt: skip
RUNS = {"runtime", "plants", "sinks", "link"}
MAKES = {"identification", "design", "tune", "export"}
LAYER = {**dict.fromkeys(CORE, 0), **dict.fromkeys(RUNS, 1), **dict.fromkeys(MAKES, 2),
         "api": 3, "cli.commands": 3, "cli.jsonout": 3, "cli.progress": 3, "commission": 3,
         "session": 3, "cli": 4,
         "__main__": 5}  # fmt: skip
# Within the makers: tune and export build on design; identification stands alone.
MAKERS_MAY_IMPORT = {
    "tune": {"design"},
    "export": {"design"},
    "design": set(),
    "identification": set(),
}


def _module(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


@functools.cache  # parsing every module once serves every test here (none changes it)
def _graph() -> dict[str, set[str]]:
    modules = {_module(p): p for p in (SRC / "cartctl").rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1]
                                    + ([base] if base else []))  # fmt: skip
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            graph[name] |= {t for t in targets if t in modules and t != name}
    graph["cartctl"].discard("cartctl.api")  # the package's lazy __getattr__ facade, on first use
    return graph


def _group(module: str) -> str:
    """The package (or root module) a module belongs to; ``cli``'s subpackages are their own."""
    parts = module.split(".")
    if len(parts) > 2 and parts[1] == "cli":
        return f"cli.{parts[2]}"
    return parts[1] if len(parts) > 1 else "cartctl"


def test_every_module_has_a_layer() -> None:
    assert {_group(m) for m in _graph()} <= set(LAYER)


def test_imports_go_down_or_sideways_only() -> None:
    wrong = []
    for module, targets in _graph().items():
        g = _group(module)
        for target in targets:
            t = _group(target)
            if (
                LAYER[t] > LAYER[g]
                or (g in MAKES and t in MAKES and t != g and t not in MAKERS_MAY_IMPORT[g])
                or (g == "runtime" and t == "design")
                or (t == "cli" and module != "cartctl.__main__")
            ):
                wrong.append(f"{module} -> {target}")
    assert wrong == []


def test_the_api_imports_nothing_of_the_command_line() -> None:
    """The API and the commands are one layer, side by side: the API's checks live below both."""
    graph = _graph()
    wrong = [
        f"{m} -> {t}"
        for m in graph
        if _group(m) == "api"
        for t in graph[m]
        if _group(t).startswith("cli")
    ]
    assert wrong == []


def test_no_circles() -> None:
    graph = _graph()
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                cycles.append([*path[path.index(target) :], target] if target in path else [target])
            elif target not in state:
                visit(target, [*path, target])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert cycles == []


def test_the_root_holds_at_most_ten_modules() -> None:
    """The package's root holds the core facts; the rest lives in packages that name a part."""
    root = sorted(p.name for p in (SRC / "cartctl").glob("*.py"))
    assert len(root) <= 10, root


def test_no_module_is_over_400_lines() -> None:
    """Small modules: one that grows past 400 lines is split (the generated MAVLink dialect in
    link/vendor is not ours to split)."""
    long = {
        str(p.relative_to(SRC)): n
        for p in (SRC / "cartctl").rglob("*.py")
        if "vendor" not in p.parts and (n := len(p.read_text(encoding="utf-8").splitlines())) > 400
    }
    assert long == {}
