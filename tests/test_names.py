"""Names that say what they are: the contracts are named where they are defined and cited by name.

The four contracts other tools rely on (trace columns, command line, ``--json`` keys, Rerun entity
paths) are defined in ``docs/architecture.md`` under stable anchors; the code cites them by what
they are, never by a number that is defined nowhere.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
CONTRACT_ANCHORS = ("trace-columns", "command-line", "json-output", "rerun-entities")


def test_no_module_cites_a_contract_by_number() -> None:
    numbered = re.compile(r"contract[ -]?[1-4]", re.I)
    found = [
        f"{path.relative_to(ROOT)}:{n}"
        for path in sorted((ROOT / "src" / "cartctl").rglob("*.py"))
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if numbered.search(line)
    ]
    assert not found, found


def test_each_contract_has_a_heading_with_a_stable_anchor() -> None:
    text = ARCHITECTURE.read_text(encoding="utf-8")
    anchors = re.findall(r"^#+ .*\{#([\w-]+)\}\s*$", text, flags=re.M)
    assert set(CONTRACT_ANCHORS) <= set(anchors)


def test_the_contracts_name_what_the_code_keeps() -> None:
    """The defined columns and entity paths are the ones the code writes (a typo in either fails)."""
    from cartctl.sinks.base import TRACE_COLUMNS, TRUE_SPEED_COLUMNS
    from cartctl.sinks.rerun_layout import ENTITY_PATHS
    from cartctl.trace import REQUIRED_COLUMNS

    text = ARCHITECTURE.read_text(encoding="utf-8")
    section = text.split("{#trace-columns}", 1)[1].split("{#command-line}", 1)[0]
    for column in (*REQUIRED_COLUMNS, *TRACE_COLUMNS, *TRUE_SPEED_COLUMNS):
        assert f"`{column}`" in section, column
    rerun = text.split("{#rerun-entities}", 1)[1]
    for column in ("reference_a", "speed_a", "estimate_a", "voltage_a", "compute_us"):
        assert f"`{ENTITY_PATHS[column]}`" in rerun, column
