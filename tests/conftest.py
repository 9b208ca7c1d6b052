"""Shared fixtures: paths to the shipped files, the report's models, a checkout-like folder, and
the rows of a Rerun recording; the hypothesis profile of the property tests."""

from __future__ import annotations

import os

# Numerics run as a cartctl process runs them (cli.console_main): one BLAS thread. On a few cores
# OpenBLAS's second thread only spins on cartctl's small matrices (about a fifth of the suite's
# CPU). Set before anything loads numpy; a limit the user set wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import contextlib
import shutil
import threading
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import settings

ROOT = Path(__file__).resolve().parents[1]

# Property tests: the same examples on every run (derandomize, no example database) and no
# per-example time limit, which a loaded machine would break. A test's own @settings adds to this.
settings.register_profile("cartctl", derandomize=True, database=None, deadline=None)
settings.load_profile("cartctl")

MODELS = ROOT / "models"


def pytest_configure(config: pytest.Config) -> None:
    """With workers: the controller compiles cartctl's sources and rewrites the test modules'
    asserts once, into the usual cache files, while the workers start; each worker (and each
    ``cartctl`` a test starts) then reads them instead of compiling all of them itself (about 2 s
    of CPU each, even where PYTHONDONTWRITEBYTECODE is set). Only a speed-up: without it every
    process compiles for itself, as before."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    threading.Thread(target=_compile_once, args=(config,), daemon=True).start()


def _compile_once(config: pytest.Config) -> None:
    import compileall

    with contextlib.suppress(Exception):
        compileall.compile_dir(ROOT / "src" / "cartctl", quiet=2)
    try:
        from _pytest.assertion import rewrite

        for source in sorted(Path(__file__).parent.glob("test_*.py")):
            pyc = rewrite.get_cache_dir(source) / (source.name[:-3] + rewrite.PYC_TAIL)
            if rewrite._read_pyc(source, pyc) is None and rewrite.try_makedirs(pyc.parent):
                source_hash, code = rewrite._rewrite_test(source, config)
                rewrite._write_pyc(config.stash[rewrite.assertstate_key], code, source_hash, pyc)
    except Exception:  # pytest's internals moved: the workers rewrite for themselves
        return


HEAVY_MODULES = frozenset({
    "test_output_faults", "test_design_cli", "test_design_pi", "test_tune_output", "test_identify",
    "test_design_analysis", "test_shipped_files", "test_commission", "test_readme_session",
    "test_identify_diagnostics", "test_report", "test_tune_robust",
})  # fmt: skip
"""Modules of several seconds of CPU each (figures, subprocesses, builds): they go out first, so
that the run ends on short modules, not on one worker still busy with a long one."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The order the workers take modules in (``--dist loadfile --no-loadscope-reorder``): one
    with real-time tests, then two without, and so on, each kind largest first (the heavy ones,
    then by number of tests). At any time about one worker waits on a real-time cart while the
    others compute, and the long waits do not all come at the end."""
    by_module: dict[str, list[pytest.Item]] = {}
    for item in items:
        by_module.setdefault(item.nodeid.split("::")[0], []).append(item)

    def realtime(group: list[pytest.Item]) -> int:
        return sum(1 for item in group if item.get_closest_marker("realtime"))

    def weight(group: list[pytest.Item]) -> tuple[bool, int]:
        return group[0].path.stem in HEAVY_MODULES, len(group)

    waiting = sorted((g for g in by_module.values() if realtime(g)), key=realtime, reverse=True)
    computing = sorted((g for g in by_module.values() if not realtime(g)), key=weight, reverse=True)
    ordered: list[pytest.Item] = []
    while waiting or computing:
        for queue, take in ((waiting, 1), (computing, 2)):
            for _ in range(take):
                if queue:
                    ordered.extend(queue.pop(0))
    items[:] = ordered


@pytest.hookimpl(optionalhook=True)  # a pytest-xdist hook; without the plugin, not called
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: two workers more than the cores this process may use. The real-time tests
    spend most of their time waiting for the cart's 10 ms ticks; the extra workers keep the cores
    busy meanwhile. On 2 cores, measured on a clean clone: 3 workers 49 s (59 s with a core busy),
    4 workers 43 s (55 s), 5 workers 47 s (56 s)."""
    return len(os.sched_getaffinity(0)) + 2


@pytest.fixture
def ground_path() -> Path:
    return MODELS / "ground.toml"


@pytest.fixture
def air_path() -> Path:
    return MODELS / "air.toml"


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder like a checkout: the shipped models and controllers, logs/ written there."""
    shutil.copytree(ROOT / "models", tmp_path / "models")
    shutil.copytree(ROOT / "controllers", tmp_path / "controllers")
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture
def rrd_rows() -> Callable[[str | Path], Counter]:
    """Rows per entity path (without the leading ``/``) of a recording's non-static chunks.

    Reading the stream needs the file's footer: a recording not closed properly fails here.
    """
    from rerun.chunk import RrdReader

    def count(path: str | Path) -> Counter:
        rows: Counter = Counter()
        for chunk in RrdReader(path).stream():
            if not chunk.is_static:
                rows[chunk.entity_path.lstrip("/")] += chunk.num_rows
        return rows

    return count


@pytest.fixture
def blueprint_views() -> Callable[[str | Path], dict[str, dict]]:
    """The views of the (first) blueprint stored in a file (.rrd or .rbl), by name: each with
    its ``origin``, ``contents`` (the query lines) and y ``range`` ((lo, hi) or None)."""
    from rerun.chunk import RrdReader

    def views(path: str | Path) -> dict[str, dict]:
        reader = RrdReader(path)
        (entry,) = reader.blueprints()[:1]
        fields: dict[str, dict] = {}
        for chunk in reader.stream(store=entry):
            batch = chunk.to_record_batch()
            parts = chunk.entity_path.strip("/").split("/")
            if parts[0] != "view" or len(parts) < 2:
                continue
            view = fields.setdefault(parts[1], {"range": None, "contents": []})
            for name in batch.schema.names:
                if ":" not in name:  # row ids and timelines
                    continue
                value = batch.column(name).to_pylist()[-1]
                if name == "ViewBlueprint:display_name":
                    view["name"] = value[0]
                elif name == "ViewBlueprint:space_origin":
                    view["origin"] = value[0]
                elif name == "ViewContents:query":
                    view["contents"] = list(value)
                elif name == "ScalarAxis:range":
                    view["range"] = tuple(value[0])
        return {view["name"]: view for view in fields.values() if "name" in view}

    return views


@pytest.fixture
def stop_handlers() -> Iterator[None]:
    """cartctl's stop-signal handlers installed, as ``cli.main`` installs them, for the test."""
    from cartctl import stopping

    previous = stopping.install()
    try:
        yield
    finally:
        stopping.restore(previous)
