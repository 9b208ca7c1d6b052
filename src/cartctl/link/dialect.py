"""The microOS MAVLink dialect: message ids, CRC_EXTRA values and frame encoding.

The cart's "generation A" firmware speaks MAVLink 1.0 (start byte 0xFE) with a custom dialect,
``microos.xml`` next to this module. pymavlink's parser derives each message's CRC_EXTRA and payload
length from that XML, and pymavlink's generator turns it into a Python module that packs and unpacks
the payloads (:func:`generated_module`). THREAD_INFO (id 1) is not in the XML because its fields are
not known; only its length and CRC_EXTRA are, as constants.

"Generation B" firmware speaks MAVLink 2 (start byte 0xFD) and sends GPIOX (id 14) instead of GPIO.
:func:`encode_gpiox_v2` builds such a frame by hand, so that a virtual cart can impersonate a
generation-B cart.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import io
import struct
import tempfile
import threading
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from types import ModuleType
from typing import Any

from pymavlink.generator import mavgen, mavparse
from pymavlink.generator.mavcrc import x25crc

__all__ = [
    "CRC_EXTRA",
    "GPIOX_CRC_EXTRA",
    "GPIOX_FLOAT_COUNT",
    "GPIO_FLOAT_COUNT",
    "GPIO_INT_COUNT",
    "MAV_TYPE_CAR",
    "MSG_EVENT",
    "MSG_GPIO",
    "MSG_GPIOX",
    "MSG_HEARTBEAT",
    "MSG_PRINT",
    "MSG_THREAD_INFO",
    "PAYLOAD_LENGTH",
    "PRINT_TEXT_BYTES",
    "STX_V1",
    "STX_V2",
    "Encoder",
    "encode_gpiox_v2",
    "generated_module",
]

MSG_HEARTBEAT = 0
MSG_THREAD_INFO = 1
MSG_GPIO = 3
MSG_EVENT = 4
MSG_PRINT = 5
MSG_GPIOX = 14
"""Message ids; GPIOX is generation B (MAVLink 2) only."""

STX_V1 = 0xFE
"""Start byte of a MAVLink 1 frame (generation A)."""
STX_V2 = 0xFD
"""Start byte of a MAVLink 2 frame (generation B)."""

MAV_TYPE_CAR = 20
"""HEARTBEAT ``type`` sent by the cart."""

GPIO_FLOAT_COUNT = 8
GPIO_INT_COUNT = 4
GPIOX_FLOAT_COUNT = 12
PRINT_TEXT_BYTES = 32
"""Capacity of one PRINT frame's text field, in bytes."""

GPIOX_CRC_EXTRA = 221
_THREAD_INFO_PAYLOAD_LENGTH = 22
_THREAD_INFO_CRC_EXTRA = 215
_MAVLINK_VERSION = 2
_SEQ_MODULO = 256
_UINT32_MAX = 0xFFFF_FFFF
_GENERATED_NAME = "cartctl_link_microos_generated"


def _dialect_xml() -> resources.abc.Traversable:
    return resources.files(__package__) / "microos.xml"


def _parse_dialect() -> tuple[dict[int, int], dict[int, int]]:
    """CRC_EXTRA and payload length per message id, from the XML (plus THREAD_INFO's constants)."""
    with resources.as_file(_dialect_xml()) as path, contextlib.redirect_stdout(io.StringIO()):
        xml = mavparse.MAVXML(str(path), "1.0")
    crc_extra = {m.id: m.crc_extra for m in xml.message}
    length = {m.id: m.wire_length for m in xml.message}
    crc_extra[MSG_THREAD_INFO] = _THREAD_INFO_CRC_EXTRA
    length[MSG_THREAD_INFO] = _THREAD_INFO_PAYLOAD_LENGTH
    return dict(sorted(crc_extra.items())), dict(sorted(length.items()))


CRC_EXTRA: dict[int, int]
PAYLOAD_LENGTH: dict[int, int]
CRC_EXTRA, PAYLOAD_LENGTH = _parse_dialect()


_GENERATE_LOCK = threading.Lock()


def generated_module() -> ModuleType:
    """The pymavlink-generated Python module of the microOS dialect, built once per process.

    mavgen writes the module into a temporary directory, from which it is imported; its progress
    output is swallowed so that nothing reaches stdout. Swallowing it swaps ``sys.stdout`` for the
    whole process, so the module is built once, at import of this module (normally in the main
    thread, before any thread of the serial path prints), under a lock.

    Returns
    -------
    ModuleType
        The module, with ``MAVLink``, ``MAVLink_gpio_message`` and so on.

    Raises
    ------
    RuntimeError
        If pymavlink fails to generate the module.
    """
    with _GENERATE_LOCK:
        return _generate()


@functools.cache
def _generate() -> ModuleType:
    sink = io.StringIO()
    with (
        resources.as_file(_dialect_xml()) as xml_path,
        tempfile.TemporaryDirectory(prefix="cartctl-mavgen-") as tmp,
        contextlib.redirect_stdout(sink),
    ):
        out = Path(tmp) / f"{_GENERATED_NAME}.py"
        opts = mavgen.Opts(output=str(out), wire_protocol="1.0", language="Python3", validate=True)
        if not mavgen.mavgen(opts, [str(xml_path)]):
            raise RuntimeError(
                f"pymavlink could not generate the microOS dialect:\n{sink.getvalue()}"
            )
        spec = importlib.util.spec_from_file_location(_GENERATED_NAME, out)
        if spec is None or spec.loader is None:
            raise RuntimeError(f"cannot import the generated dialect module {out}")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    return module


def _check_uint32(name: str, value: int) -> None:
    if not 0 <= value <= _UINT32_MAX:
        raise ValueError(f"{name} must be in 0..{_UINT32_MAX}, got {value}")


def _utf8_chunks(text: str, size: int) -> list[bytes]:
    """Split the UTF-8 bytes of ``text`` into chunks of at most ``size`` bytes, on char bounds."""
    raw = text.encode("utf-8")
    chunks: list[bytes] = []
    start = 0
    while start < len(raw):
        end = min(start + size, len(raw))
        # Do not cut a multi-byte character: back up over continuation bytes (10xxxxxx).
        while end < len(raw) and end > start + 1 and (raw[end] & 0xC0) == 0x80:
            end -= 1
        chunks.append(raw[start:end])
        start = end
    return chunks


class Encoder:
    """Encodes generation-A (MAVLink 1) frames with a running sequence number.

    Parameters
    ----------
    sysid, compid
        Source system and component written into every frame (QRC and the cart use 0, 0).

    Attributes
    ----------
    seq : int
        Sequence number of the next frame, 0..255; every frame consumes one and it wraps.
    """

    def __init__(self, sysid: int = 0, compid: int = 0) -> None:
        self.sysid = sysid
        self.compid = compid
        self.seq = 0
        self._mav: Any = generated_module().MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def _pack(self, message: Any) -> bytes:
        self._mav.seq = self.seq
        frame = bytes(message.pack(self._mav))
        self.seq = (self.seq + 1) % _SEQ_MODULO
        return frame

    def gpio(self, time_ms: int, floats: Sequence[float], ints: Sequence[int]) -> bytes:
        """One GPIO frame.

        Parameters
        ----------
        time_ms
            Sender time in ms (uint32).
        floats
            The 8 float channels (sent as float32).
        ints
            The 4 int channels (int32).

        Returns
        -------
        bytes
            The 60-byte frame.

        Raises
        ------
        ValueError
            On a wrong number of channels or a value that does not fit its wire type.
        """
        if len(floats) != GPIO_FLOAT_COUNT or len(ints) != GPIO_INT_COUNT:
            raise ValueError(
                f"GPIO needs {GPIO_FLOAT_COUNT} floats and {GPIO_INT_COUNT} ints, "
                f"got {len(floats)} and {len(ints)}"
            )
        _check_uint32("time_ms", time_ms)
        message = generated_module().MAVLink_gpio_message(
            time_ms, [float(x) for x in floats], [int(i) for i in ints]
        )
        try:
            return self._pack(message)
        except (struct.error, OverflowError) as exc:
            raise ValueError(f"GPIO channel value does not fit its wire type: {exc}") from exc

    def heartbeat(self, time_ms: int, type: int = MAV_TYPE_CAR, data: bytes = bytes(8)) -> bytes:
        """One HEARTBEAT frame (``mavlink_version`` 2).

        Parameters
        ----------
        time_ms
            Sender time in ms (uint32).
        type
            Vehicle type, 20 (car) by default.
        data
            The 8 data bytes (unused by microOS).

        Returns
        -------
        bytes
            The 22-byte frame.
        """
        if len(data) != 8:
            raise ValueError(f"HEARTBEAT data must be 8 bytes, got {len(data)}")
        _check_uint32("time_ms", time_ms)
        message = generated_module().MAVLink_heartbeat_message(
            time_ms, type, list(data), _MAVLINK_VERSION
        )
        try:
            return self._pack(message)
        except struct.error as exc:
            raise ValueError(f"HEARTBEAT field out of range: {exc}") from exc

    def event(self, type: int) -> bytes:
        """One EVENT frame (``type`` 1000..1007 are QRC's buttons 0..7)."""
        if not 0 <= type <= 0xFFFF:
            raise ValueError(f"EVENT type must be in 0..65535, got {type}")
        return self._pack(generated_module().MAVLink_event_message(type))

    def print_text(self, text: str) -> list[bytes]:
        """PRINT frames carrying ``text`` (UTF-8), split into chunks of at most 32 bytes.

        A multi-byte character is never split over two frames. An empty text gives no frame.

        Raises
        ------
        ValueError
            If ``text`` contains a NUL character (the receiver would cut the text there).
        """
        if "\x00" in text:
            raise ValueError("PRINT text must not contain NUL characters")
        module = generated_module()
        return [
            self._pack(module.MAVLink_print_message(chunk))
            for chunk in _utf8_chunks(text, PRINT_TEXT_BYTES)
        ]


def encode_gpiox_v2(
    time_ms: int,
    floats: Sequence[float],
    *,
    seq: int = 0,
    sysid: int = 0,
    compid: int = 0,
) -> bytes:
    """A generation-B GPIOX frame (MAVLink 2, id 14): time and 12 float channels.

    Trailing zero bytes of the 52-byte payload are truncated, as MAVLink 2 does (at least one byte
    stays). The frame is unsigned (incompat flags 0).

    Parameters
    ----------
    time_ms
        Sender time in ms (uint32).
    floats
        The 12 float channels (sent as float32).
    seq, sysid, compid
        Header fields, 0..255 each.

    Returns
    -------
    bytes
        The frame, 13 to 64 bytes long.
    """
    if len(floats) != GPIOX_FLOAT_COUNT:
        raise ValueError(f"GPIOX needs {GPIOX_FLOAT_COUNT} floats, got {len(floats)}")
    _check_uint32("time_ms", time_ms)
    try:
        payload = struct.pack(f"<I{GPIOX_FLOAT_COUNT}f", time_ms, *floats).rstrip(b"\x00")
    except (struct.error, OverflowError) as exc:
        raise ValueError(f"GPIOX channel value does not fit float32: {exc}") from exc
    payload = payload or b"\x00"
    header = bytes([len(payload), 0, 0, seq, sysid, compid]) + MSG_GPIOX.to_bytes(3, "little")
    crc = x25crc(header + payload)
    crc.accumulate(bytes([GPIOX_CRC_EXTRA]))
    return bytes([STX_V2]) + header + payload + crc.crc.to_bytes(2, "little")


generated_module()  # built now, at import, before any thread of the serial path runs
