"""QRoboticsCenter (QRC, the course's PC program) GPIO logs read into labels and text fields.

- QRC 5, XML: a ``<QGPIORecord>`` root with ``<labels>`` (``time``, 8 float and 4 int labels) and
  ``<data>`` holding one tab-separated ``<row>`` per sample: time (ms), 8 floats, 4 ints.
- QRC 6, CSV: line 1 ``QGPIORecord, QRC v<version>, <date @ time>, ...``, line 2
  ``Time, <12 labels>``, then one ``", "``-separated line per sample: time (ms) and 12 floats.

:mod:`cartctl.data.read` turns the fields into numbers and the channels into trace columns.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from cartctl.errors import DataFileError

QRC5_DEFAULT_LABELS: tuple[str, ...] = tuple(f"FloatIn{k}" for k in range(8)) + tuple(
    f"IntIn{k}" for k in range(4)
)
"""The channel labels QRC 5 uses when the user named none."""

_RECORD_KIND = re.compile(r"Q\w*Record")


@dataclass(frozen=True)
class QrcLog:
    """A QRC GPIO log as text: ``kind`` ("QRC 5 XML" or "QRC 6 CSV"), the channel ``labels``
    (time excluded), ``rows`` of fields (time in ms first), the 1-based line of each row (None
    for XML, whose rows are counted) and whether it lacked its closing tags (``truncated``)."""

    kind: str
    version: str | None
    labels: tuple[str, ...]
    rows: list[list[str]]
    row_lines: list[int] | None
    truncated: bool = False


def detect(head: str) -> str | None:
    """``"qrc5"`` for XML, ``"qrc6"`` for a CSV whose first field names a QRC record type, else
    None, from the start of a file (without byte-order mark and leading white space)."""
    if head.startswith("<"):
        return "qrc5"
    first_field = head.split("\n", 1)[0].split(",", 1)[0].strip()
    if _RECORD_KIND.fullmatch(first_field):
        return "qrc6"
    return None


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
    return QrcLog("QRC 5 XML", root.findtext("version"), labels, rows, None, truncated)


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
    version = preamble[1].removeprefix("QRC").strip().removeprefix("v") or None
    header = [field.strip() for field in lines[1].split(",")] if len(lines) > 1 else []
    if not header or header[0].lower() != "time":
        raise DataFileError(
            path,
            "expected the column header 'Time, <label>, <label>, ...' on line 2",
            line=2,
        )
    rows: list[list[str]] = []
    row_lines: list[int] = []
    for number, line in enumerate(lines[2:], start=3):
        if line.strip():
            rows.append(line.split(","))
            row_lines.append(number)
    if not rows:
        raise DataFileError(path, "the log has no data rows after its header (line 2)")
    return QrcLog("QRC 6 CSV", version, tuple(header[1:]), rows, row_lines)


def _read_text(path: Path) -> str:
    """The file as text: UTF-8, or else Latin-1 (QRC on Windows writes the local code page)."""
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def column_name(label: str, index: int, kind: str, *, lower: bool = True) -> str:
    """A QRC channel label as a trace column name: ``"voltage A [V]"`` → ``"voltage_a_v"``.

    Runs of other characters than letters and digits become one ``_``, ``ch_`` goes before a
    leading digit, and an empty label (at ``index``) gives the QRC 5 default label or
    ``channel<index>``; ``lower=False`` keeps the case (a channel kept as an extra column).
    """
    name = re.sub(r"[^0-9A-Za-z]+", "_", label.lower() if lower else label).strip("_")
    if not name:
        if kind.startswith("QRC 5") and index < len(QRC5_DEFAULT_LABELS):
            default = QRC5_DEFAULT_LABELS[index]
            return default.lower() if lower else default
        return f"channel{index}"
    return f"ch_{name}" if name[0].isdigit() else name
