"""The file side of a trace: QRoboticsCenter (QRC, the course's PC program) GPIO logs read into
labels and text fields (the QRC 5 XML and QRC 6 CSV layouts: docs/serial-protocol.md), and which
file column becomes which trace column (the trace's own names, or a ``--map``, trace column → file
column or QRC label, and where it is silent a column named like a trace column)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from cartctl.data.trace import _MAP_FORM, MOTORS, REQUIRED_COLUMNS, _check_name
from cartctl.errors import DataFileError, InputError

QRC5_DEFAULT_LABELS: tuple[str, ...] = tuple(f"FloatIn{k}" for k in range(8)) + tuple(
    f"IntIn{k}" for k in range(4)
)
"""The channel labels QRC 5 uses when the user named none."""


@dataclass(frozen=True)
class QrcLog:
    """A QRC GPIO log as text: ``kind`` ("QRC 5 XML" or "QRC 6 CSV"), the channel ``labels``
    (time excluded), ``rows`` of fields (time in ms first), the 1-based line of each row (None
    for XML, whose rows are counted) and whether it lacked its closing tags (``truncated``)."""

    kind: str
    labels: tuple[str, ...]
    rows: list[list[str]]
    row_lines: list[int] | None
    truncated: bool = False


def read_qrc5(path: Path) -> QrcLog:
    """A QRC 5 XML GPIO log; one QRC did not close is read up to its last complete row."""
    text = _read_text(path)
    truncated = False
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        root, truncated = _recover_truncated(path, text, err), True
    if root.tag != "QGPIORecord":
        raise DataFileError(
            path,
            f"this XML holds a <{root.tag}>, not a QRC GPIO log; expected the root <QGPIORecord>",
        )
    labels_el = root.find("labels")
    values = [] if labels_el is None else [(v.text or "").strip() for v in labels_el.iter("value")]
    if values and values[0].lower() == "time":
        values = values[1:]
    labels = tuple(values) if values else QRC5_DEFAULT_LABELS
    data_el = root.find("data")
    rows = [] if data_el is None else [(r.text or "").split() for r in data_el.iter("row")]
    if not rows:
        raise DataFileError(path, "the log has no data rows (<data> holds no <row>)")
    return QrcLog("QRC 5 XML", labels, rows, None, truncated)


def _recover_truncated(path: Path, text: str, err: ET.ParseError) -> ET.Element:
    """Parse a QRC 5 log cut off before its closing tags, or raise the parse error as ours."""
    line = err.position[0] if err.position else None
    problem = f"cannot parse the XML ({err.msg.split(': line')[0]}); expected a QRC 5 GPIO log"
    cut = text.rfind("</row>")
    if "</QGPIORecord>" in text or "<QGPIORecord>" not in text or cut < 0:
        raise DataFileError(path, problem, line=line) from err
    try:
        return ET.fromstring(text[: cut + len("</row>")] + "\n</data>\n</QGPIORecord>\n")
    except ET.ParseError:
        raise DataFileError(path, problem, line=line) from err


def read_qrc6(path: Path) -> QrcLog:
    """A QRC 6 CSV GPIO log, with the line of each row."""
    lines = _read_text(path).splitlines() or [""]
    preamble = [field.strip() for field in lines[0].split(",")]
    if preamble[0] != "QGPIORecord":
        raise DataFileError(
            path,
            f"this is a QRC {preamble[0]} log; only GPIO logs (QGPIORecord) hold voltages and "
            "speeds",
            line=1,
        )
    if len(preamble) < 2:
        raise DataFileError(
            path,
            "this looks like an early QRC text log ('QGPIORecord' alone on line 1), which is not "
            "supported; expected a QRC 6 CSV ('QGPIORecord, QRC v<version>, ...') or a QRC 5 XML",
            line=1,
        )
    header = [field.strip() for field in lines[1].split(",")] if len(lines) > 1 else []
    if not header or header[0].lower() != "time":
        raise DataFileError(
            path,
            "expected the column header 'Time, <label>, <label>, ...' on line 2",
            line=2,
        )
    numbered = [(number, line) for number, line in enumerate(lines[2:], start=3) if line.strip()]
    rows, row_lines = [line.split(",") for _, line in numbered], [number for number, _ in numbered]
    if not rows:
        raise DataFileError(path, "the log has no data rows after its header (line 2)")
    return QrcLog("QRC 6 CSV", tuple(header[1:]), rows, row_lines)


def _read_text(path: Path) -> str:
    """The file as text: UTF-8, or else Latin-1 (QRC on Windows writes the local code page)."""
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def column_name(label: str, index: int, kind: str, *, lower: bool = True) -> str:
    """A QRC channel label as a trace column name: ``"voltage A [V]"`` → ``"voltage_a_v"`` (``ch_``
    before a leading digit; for an empty label at ``index``, the QRC 5 default label or
    ``channel<index>``); ``lower=False`` keeps the case."""
    name = re.sub(r"[^0-9A-Za-z]+", "_", label.lower() if lower else label).strip("_")
    if not name:
        if kind.startswith("QRC 5") and index < len(QRC5_DEFAULT_LABELS):
            default = QRC5_DEFAULT_LABELS[index]
            return default.lower() if lower else default
        return f"channel{index}"
    return f"ch_{name}" if name[0].isdigit() else name


def check_mapping(mapping: Mapping[str, str]) -> dict[str, str]:
    checked: dict[str, str] = {}
    for name, label in mapping.items():
        _check_name(name)
        if not isinstance(label, str) or not label.strip():
            raise InputError(f"the mapping gives {name} no label ({label!r}); expected {_MAP_FORM}")
        checked[name] = label.strip()
        other = next((o for o in checked if o != name and checked[o] == checked[name]), name)
        if re.sub("_[ab]$", "", other) != re.sub("_[ab]$", "", name):  # one reference for both: ok
            raise InputError(
                f"the mapping gives {checked[name]!r} to both {other} and {name}; "
                "map each to its own channel"
            )
    return checked


def plan_columns(
    path: Path, kind: str, names: list[str], mapping: dict[str, str] | None, header_line: int | None
) -> tuple[int, dict[str, int | None]]:
    """The time column's index and, per trace column, its file column (None: zeros); a QRC log's
    ``names`` start with its time column, which always gives time_s."""
    monitor = kind == "CSV" and names[:2] == ["time_s", "tick"]
    if kind == "CSV" and mapping is None:  # the trace's own names, or a monitor's labels
        missing = [name for name in REQUIRED_COLUMNS if name not in names]
        if missing and monitor:
            mapping = monitor_mapping(names[2:])
        elif missing:
            hint = ""
            if len(names) == 1 and (";" in names[0] or "\t" in names[0]):
                hint = "; the columns seem separated by ';' or tabs, but trace files use ','"
            raise DataFileError(
                path,
                f"missing required column(s) {', '.join(missing)}; the header has "
                f"{', '.join(names)}; a trace needs {', '.join(REQUIRED_COLUMNS)}{hint}",
                line=header_line,
            )
    mapping = mapping or {}
    first = 0 if kind == "CSV" else 1  # QRC: names[0] is the time column
    what = "column" if kind == "CSV" else "channel"
    listing = ", ".join(names[first:])
    if first and "time_s" in mapping:
        raise DataFileError(
            path,
            f"a {kind} log carries its own time (ms), which becomes time_s; "
            f"drop time_s={mapping['time_s']} from the mapping",
        )
    auto = [n if not first else column_name(n, j - 1, kind) for j, n in enumerate(names)]
    kept = [
        n if not first else column_name(n, j - 1, kind, lower=False) for j, n in enumerate(names)
    ]
    source = {"time_s": 0} if first else {}
    for name, label in mapping.items():
        hits = [j for j, n in enumerate(names) if n == label and j >= first]
        if len(hits) != 1:
            problem = "lacks" if not hits else f"has {len(hits)} times"
            raise DataFileError(
                path,
                f"the mapping {name}={label} names {what} {label!r}, which this {kind} file "
                f"{problem}; its {what}s are {listing}",
            )
        source[name] = hits[0]
    # A motor's voltage or speed named like the trace column, only with its partner (never half)
    explicit = set(source.values())
    partners = {f"voltage_{m}": f"speed_{m}" for m in MOTORS}
    partners |= {speed: voltage for voltage, speed in partners.items()}
    for name in REQUIRED_COLUMNS:
        if name in source or name not in auto[first:] or auto.index(name) in explicit:
            continue
        partner = partners.get(name)
        if partner is None or partner in source or partner in auto[first:]:
            source[name] = auto.index(name)
    _counterparts(names, first, mapping, source)
    if "time_s" not in source:
        raise DataFileError(
            path,
            f"no time column: the header has {listing}; say which column holds the time (s) "
            "with --map time_s=<column>",
            line=header_line,
        )
    for motor in MOTORS:
        pair = [f"voltage_{motor}", f"speed_{motor}"]
        have = [name for name in pair if name in source]
        if len(have) == 1:
            lack = pair[1 - pair.index(have[0])]
            raise DataFileError(
                path,
                f"{have[0]} comes from {what} {names[source[have[0]]]!r} but {lack} from none; "
                f"map both of motor {motor}'s columns, or neither",
            )
    if not any(f"voltage_{motor}" in source for motor in MOTORS):
        example = _guess_mapping(names[first:])
        if monitor:
            unnamed = ", ".join(n for n in REQUIRED_COLUMNS[1:] if n not in source)
            if {"FloatIn0", "FloatIn2", "FloatIn4"} <= set(names):
                example = "voltage_a=FloatIn2,speed_a=FloatIn0,reference_a=FloatIn4 (the export's)"
            raise DataFileError(
                path,
                f"a 'cartctl monitor' trace whose labels name none of {unnamed}; its channels "
                f"are {', '.join(names[2:])}; record with {MONITOR_LABELS_HINT}, or say which "
                f"is which with --map {example}",
            )
        raise DataFileError(
            path,
            f"no mapping for voltage/speed columns; this {kind} file has {what}s {listing}; "
            f"say which is which with --map {example}",
        )
    plan = {name: source.get(name) for name in REQUIRED_COLUMNS}
    taken = set(REQUIRED_COLUMNS) | set(source)
    used = set(source.values())
    for j in range(first, len(names)):  # extras, in file order
        plan |= {name: k for name, k in source.items() if k == j and name not in plan}
        if j not in used and auto[j] not in taken:
            name, suffix = kept[j], 2
            while name in plan:
                name, suffix = f"{kept[j]}_{suffix}", suffix + 1
            plan[name] = j
    return source["time_s"], plan


MONITOR_LABELS_HINT = (
    "--labels f0=speed_a,f1=speed_b,f2=voltage_a,f3=voltage_b,f4=reference_a,f5=reference_b "
    "(the out channels of 'cartctl export --arduino')"
)
MONITOR_NAMES = (*REQUIRED_COLUMNS[1:], "reference_a", "reference_b", "estimate_a", "estimate_b")


def label_key(label: str) -> str:
    """A label without case and separators: ``speedA``, ``speed_a`` and ``Speed-A`` agree."""
    return re.sub(r"[^0-9a-z]", "", label.lower())


def monitor_mapping(labels: Sequence[str]) -> dict[str, str]:
    """Trace column → the one monitor label equal to its name but for case and separators."""
    hits = {name: [label for label in labels if label_key(label) == label_key(name)]
            for name in MONITOR_NAMES}  # fmt: skip
    return {name: found[0] for name, found in hits.items() if len(found) == 1}


_MOTOR_LETTER = {m: re.compile(rf"(?:(?<![A-Za-z])[{m}{m.upper()}]|(?<=[a-z]){m.upper()})(?![a-z])")
                 for m in MOTORS}  # fmt: skip


def counterpart_label(label: str, motor: str, other: str) -> str | None:
    """The other motor's label (``voltA`` → ``voltB``, ``voltage A [V]`` → ``voltage B [V]``) by
    the last motor letter that stands apart or ends a camelCase word; None without one."""
    hits = list(_MOTOR_LETTER[motor].finditer(label))
    if not hits:
        return None
    at = hits[-1].start()
    letter = other.upper() if label[at].isupper() else other
    return label[:at] + letter + label[at + 1 :]


def _counterparts(
    names: list[str], first: int, mapping: Mapping[str, str], source: dict[str, int]
) -> None:
    """A mapping of one motor's pair (``voltA``, ``speedA``) also maps the other's counterparts
    (``voltB``, ``speedB``) when both exist and nothing else maps that motor."""
    used = set(source.values())
    for motor, other in (("a", "b"), ("b", "a")):
        pair = (f"voltage_{motor}", f"speed_{motor}")
        wanted = (f"voltage_{other}", f"speed_{other}")
        if not all(n in mapping for n in pair) or any(n in source for n in wanted):
            continue
        found: dict[str, int] = {}
        for name, want in zip(pair, wanted, strict=True):
            label = counterpart_label(mapping[name], motor, other)
            hits = [j for j, n in enumerate(names) if n == label and j >= first]
            if len(hits) == 1 and hits[0] not in used:
                found[want] = hits[0]
        if len(found) == 2:
            source.update(found)
            used.update(found.values())


def _guess_mapping(labels: Sequence[str]) -> str:
    """A ``--map`` example from labels whose words say what they are (never by position)."""

    def first(words: tuple[str, ...]) -> str | None:
        return next((lab for lab in labels if any(w in lab.lower() for w in words)), None)

    volt, speed = first(("volt", "u_", "pwm")), first(("speed", "omega", "vel", "rad_s", "rads"))
    if volt is None or speed is None:
        return "voltage_a=<label>,speed_a=<label> (no label says which channel is which)"
    return f"voltage_a={volt},speed_a={speed}"
