"""QRoboticsCenter (QRC) GPIO logs: their structure, read into labelled rows of text fields.

QRC is the course's PC program; its GPIO logs are the data people already have. This module knows
the two layouts (see docs/serial-protocol.md, section 6) and nothing else: it returns the channel
labels and each sample's fields as text. :mod:`cartctl.data`, the first stage of the pipeline
(data → identify → ...), detects the format, converts the fields to numbers, checks them and maps
the channels onto trace columns.

- QRC 5 (generation A), XML: a ``<QGPIORecord>`` root with ``<labels>`` (``time``, 8 float and 4 int
  labels) and ``<data>`` holding one tab-separated ``<row>`` per GPIO: time (ms), 8 floats, 4 ints.
- QRC 6 (generation B), CSV: line 1 ``QGPIORecord, QRC v<version>, <date @ time>, ...``, line 2
  ``Time, <12 labels>``, then one ``", "``-separated line per GPIOX: time (ms) and 12 floats.
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
"""The channel labels QRC 5 uses when the user named none (the time column excluded)."""

_RECORD_KIND = re.compile(r"Q\w*Record")


@dataclass(frozen=True)
class QrcLog:
    """A QRC GPIO log, as text.

    Attributes
    ----------
    kind : str
        ``"QRC 5 XML"`` or ``"QRC 6 CSV"``, for messages.
    version : str or None
        The version the log states (QRC 5: the record format; QRC 6: the QRC program).
    labels : tuple of str
        The channel labels, in column order, without the time column.
    rows : list of list of str
        One entry per sample: the time (ms), then one field per label, still as text.
    row_lines : list of int or None
        The 1-based line of each row in the file (QRC 6), or None when rows are counted
        instead (QRC 5 XML, where ``row 1`` is the first ``<row>`` element).
    truncated : bool
        True when the log lacked its closing tags and was read up to its last complete row.
    """

    kind: str
    version: str | None
    labels: tuple[str, ...]
    rows: list[list[str]]
    row_lines: list[int] | None
    truncated: bool = False


def detect(head: str) -> str | None:
    """Tell a QRC log from its first characters.

    Parameters
    ----------
    head : str
        The start of the file, with any byte-order mark and leading white space removed.

    Returns
    -------
    str or None
        ``"qrc5"`` for XML, ``"qrc6"`` for a CSV whose first field names a QRC record type
        (``QGPIORecord``, ``QPositionRecord``, ...), None for anything else.
    """
    if head.startswith("<"):
        return "qrc5"
    first_field = head.split("\n", 1)[0].split(",", 1)[0].strip()
    if _RECORD_KIND.fullmatch(first_field):
        return "qrc6"
    return None


def read_qrc5(path: Path) -> QrcLog:
    """Read a QRC 5 XML GPIO log.

    A log whose closing tags are missing (QRC stopped before it closed the file) is read up to
    its last complete row, and marked ``truncated``.

    Parameters
    ----------
    path : Path
        The ``.xml`` file.

    Returns
    -------
    QrcLog
        Labels and rows as text; ``row_lines`` is None (rows are counted).

    Raises
    ------
    DataFileError
        Not well-formed XML, another record type, or no data rows.
    """
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
    """Read a QRC 6 CSV GPIO log.

    Parameters
    ----------
    path : Path
        The ``.csv`` file; its first field is ``QGPIORecord``.

    Returns
    -------
    QrcLog
        Labels and rows as text, with the line of each row.

    Raises
    ------
    DataFileError
        Another record type, an early text log, a bad ``Time, ...`` header, or no data rows.
    """
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


def column_name(label: str, index: int, kind: str) -> str:
    """Turn a QRC channel label into a trace column name.

    Parameters
    ----------
    label : str
        The label as the log gives it (``"speedA"``, ``"FloatIn3"``, ``"voltage A [V]"``).
    index : int
        The channel's 0-based position among the labels, used when the label is empty.
    kind : str
        The log's :attr:`QrcLog.kind`, which decides the fallback name.

    Returns
    -------
    str
        Lower case, with each run of characters other than letters and digits turned into one
        ``_`` (``"voltage_a_v"``), and ``ch_`` in front of a leading digit. An empty label gives
        the QRC 5 default label (``floatin3``) or ``channel<index>``.
    """
    name = re.sub(r"[^0-9a-z]+", "_", label.lower()).strip("_")
    if not name:
        if kind.startswith("QRC 5") and index < len(QRC5_DEFAULT_LABELS):
            return QRC5_DEFAULT_LABELS[index].lower()
        return f"channel{index}"
    return f"ch_{name}" if name[0].isdigit() else name
