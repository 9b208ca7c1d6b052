"""Property tests: whatever a user hands cartctl, the answer is a result or one clear line.

Hypothesis generates trace files (CSV and QRC logs, near-valid and garbage), reference specs,
``--map`` texts, model files and controller files (the shipped ones with values, keys and lines
changed). Every reader must return a result or raise :class:`~cartctl.errors.CartctlError` (which
the command line prints as one line with exit code 2): any other exception is a traceback. A
``run`` from the command line with a generated reference spec ends with 0 or 2, one line on
stderr. The examples are seeded (``derandomize``): the suite stays deterministic.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cartctl.cli import main
from cartctl.data.modelfile import load_models
from cartctl.data.read import read_trace
from cartctl.data.trace import parse_mapping
from cartctl.design.controllerfile import build_controllers, load_controller
from cartctl.errors import CartctlError
from cartctl.reference import reference_signal

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = settings(
    max_examples=150, deadline=None, derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)  # fmt: skip

NUMBER_TEXT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(["", "nan", "inf", "-inf", "1e400", "-1e-400", "0x10", "1,5", "abc", " "]),
)
COLUMNS = ["time_s", "voltage_a", "voltage_b", "speed_a", "speed_b", "tick", "x", "", "time_s"]


def _refused_in_one_line(call, *args, **kwargs):
    """Run a reader: its result, or None after a one-line CartctlError. Other errors fail."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return call(*args, **kwargs)
        except CartctlError as exc:
            message = str(exc)
            assert message and "\n" not in message, repr(message)
            return None


@st.composite
def csv_texts(draw: st.DrawFn) -> str:
    header = draw(st.lists(st.sampled_from(COLUMNS), min_size=0, max_size=7))
    if draw(st.booleans()):
        header = ["time_s", "voltage_a", "voltage_b", "speed_a", "speed_b", *header]
    sep = draw(st.sampled_from([",", ",", ";", "\t"]))
    rows = draw(st.lists(st.lists(NUMBER_TEXT, max_size=len(header) + 1), max_size=12))
    lines = [sep.join(header)] + [sep.join(row) for row in rows]
    return "\n".join(lines) + draw(st.sampled_from(["", "\n", "\n\n"]))


@st.composite
def qrc_texts(draw: st.DrawFn) -> str:
    labels = draw(st.lists(st.sampled_from(["speedA", "voltA", "FloatIn3", "Error", "", "x y"]),
                           max_size=13))  # fmt: skip
    if draw(st.booleans()):  # QRC 6
        rows = draw(st.lists(st.lists(NUMBER_TEXT, max_size=len(labels) + 2), max_size=8))
        return "\n".join(
            ["QGPIORecord, QRC v6.0.2, 14-03-2024 @ 10:05:31, Ubuntu, x86_64",
             ", ".join(["Time", *labels]), *(", ".join(r) for r in rows)]
        )  # fmt: skip
    rows = draw(st.lists(st.lists(NUMBER_TEXT, max_size=len(labels) + 2), max_size=8))
    body = "".join(f"<row>{chr(9).join(r)}</row>" for r in rows)
    values = "".join(f"<value>{lab}</value>" for lab in ["time", *labels])
    text = f"<QGPIORecord><labels>{values}</labels><data>{body}</data></QGPIORecord>"
    return text[: draw(st.integers(0, len(text)))] if draw(st.booleans()) else text


@given(text=st.one_of(csv_texts(), qrc_texts(), st.text(max_size=200)))
@SETTINGS
def test_any_trace_file_reads_or_is_refused_in_one_line(tmp_path: Path, text: str) -> None:
    path = tmp_path / "t.csv"
    path.write_text(text, encoding="utf-8")
    trace = _refused_in_one_line(read_trace, path)
    if trace is not None:
        columns = trace.columns()
        assert all(np.isfinite(v).all() for v in columns.values())
        assert np.all(np.diff(trace.time_s) > 0)
        assert np.abs(trace.voltage_a).max(initial=0.0) <= 12.5


@given(
    text=st.one_of(
        st.text(max_size=60),
        st.lists(
            st.tuples(st.sampled_from(["voltage_a", "speed_a", "time_s", "bogus", ""]),
                      st.sampled_from(["=", "", "=="]), st.text(max_size=8)),
            max_size=5,
        ).map(lambda items: ",".join(a + b + c for a, b, c in items)),
    )
)  # fmt: skip
@SETTINGS
def test_any_map_parses_or_is_refused_in_one_line(text: str) -> None:
    mapping = _refused_in_one_line(parse_mapping, text)
    if mapping is not None:
        assert mapping and all(isinstance(k, str) and v for k, v in mapping.items())


SPEC_KINDS = ["step", "square", "ramp", "const", "file", "sine", ""]


@given(
    spec=st.one_of(
        st.text(max_size=30),
        st.tuples(st.sampled_from(SPEC_KINDS), st.lists(NUMBER_TEXT, max_size=3)).map(
            lambda kv: ":".join([kv[0], *kv[1]])
        ),
    ),
    n=st.integers(1, 500),
)
@SETTINGS
def test_any_reference_spec_gives_finite_values_or_one_line(spec: str, n: int) -> None:
    ref = _refused_in_one_line(reference_signal, spec, n, 0.01, "a")
    if ref is not None:
        assert ref.shape == (n,) and np.isfinite(ref).all()


def _mutations(text: str) -> st.SearchStrategy[str]:
    """The text with some numbers replaced, some lines dropped or some keys renamed."""
    numbers = [m.span() for m in re.finditer(r"-?\d+(\.\d+)?(e-?\d+)?", text)]
    lines = text.splitlines()

    @st.composite
    def mutate(draw: st.DrawFn) -> str:
        out = text
        kind = draw(st.sampled_from(["numbers", "lines", "keys", "cut"]))
        if kind == "numbers" and numbers:
            picks = draw(st.lists(st.integers(0, len(numbers) - 1), min_size=1, max_size=4,
                                  unique=True))  # fmt: skip
            for i in sorted(picks, reverse=True):
                a, b = numbers[i]
                value = draw(st.one_of(
                    st.sampled_from(["nan", "inf", "-inf", "1e300", "-1e300", "0", "-1", "1e-300",
                                     '"x"', "[]", "true", "1e400"]),
                    st.floats(allow_nan=False, allow_infinity=False).map(repr),
                ))  # fmt: skip
                out = out[:a] + value + out[b:]
        elif kind == "lines" and lines:
            drop = draw(st.lists(st.integers(0, len(lines) - 1), min_size=1, max_size=3))
            out = "\n".join(line for i, line in enumerate(lines) if i not in drop)
        elif kind == "keys":
            key = draw(st.sampled_from(sorted(set(re.findall(r"^(\w+) =", text, flags=re.M)))))
            out = re.sub(rf"^{key} =", draw(st.sampled_from(["x =", f"{key}_ =", "="])), text,
                         count=1, flags=re.M)  # fmt: skip
        else:
            out = text[: draw(st.integers(0, len(text)))]
        return out

    return mutate()


MODEL_TEXT = (ROOT / "models" / "ground.toml").read_text(encoding="utf-8")


@given(text=st.one_of(_mutations(MODEL_TEXT), st.text(max_size=100)))
@SETTINGS
def test_any_model_file_loads_or_is_refused_in_one_line(tmp_path: Path, text: str) -> None:
    path = tmp_path / "m.toml"
    path.write_text(text, encoding="utf-8")
    models = _refused_in_one_line(load_models, path)
    if models is not None:
        for model in models.motors.values():
            assert all(math.isfinite(v) for v in (*model.ar, *model.b))
            assert model.nk >= 0


@pytest.mark.parametrize("name", ["pi.toml", "poles.toml"])
def test_any_controller_file_loads_or_is_refused_in_one_line(tmp_path: Path, name: str) -> None:
    text = (ROOT / "controllers" / name).read_text(encoding="utf-8")
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "ground.toml").write_text(MODEL_TEXT, encoding="utf-8")
    (tmp_path / "controllers").mkdir()

    @given(mutated=_mutations(text))
    @SETTINGS
    def check(mutated: str) -> None:
        path = tmp_path / "controllers" / "c.toml"
        path.write_text(mutated, encoding="utf-8")
        controller = _refused_in_one_line(load_controller, path)
        if controller is not None:
            controllers = _refused_in_one_line(build_controllers, controller)
            if controllers is not None:
                for ctrl in controllers.values():
                    u = ctrl.step(5.0, 0.0)
                    assert math.isfinite(u)

    check()


@given(
    spec=st.tuples(st.sampled_from(["step", "square", "ramp", "const"]),
                   st.lists(NUMBER_TEXT, min_size=1, max_size=2)).map(
        lambda kv: ":".join([kv[0], *kv[1]])
    )
)  # fmt: skip
@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip
def test_run_with_any_reference_ends_in_0_or_one_line_and_2(
    capsys: pytest.CaptureFixture[str], workdir: Path, spec: str
) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            code = main(["run", "--fast", "--duration", "0.2", "--rerun", "off", "--reference",
                         spec, "--name", "p"])  # fmt: skip
        except SystemExit as exc:
            code = int(exc.code or 0)
    _, err = capsys.readouterr()
    errors = [line for line in err.splitlines() if "error" in line]
    assert code in (0, 2), err
    if code == 2:
        assert len(errors) == 1
