"""The JSON the gateway publishes, and the values ``{topic}/set/{tag}`` accepts.

A scan message::

    {"plc": "press1", "group": "fast", "scan": 12, "timestamp": 1767225600.25,
     "duration": 0.0021, "error": null,
     "values": {"temp": {"value": 71.25, "quality": "GOOD", "timestamp": 1767225600.25},
                "count": {"value": 17, "quality": "STALE", "timestamp": 1767225599.25,
                          "error": "FinsTimeout: ..."}}}

Timestamps are Unix seconds (float). Floats that JSON cannot carry are sent as the strings
``"NaN"``, ``"Infinity"`` and ``"-Infinity"``. A set payload is a JSON value (``42``, ``21.5``,
``true``, ``"text"``) or ``{"value": ..., "id": ...}``; the reply repeats the ``id``.
"""

from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Sequence
from typing import Any

from ..poller import GoodReadings, Quality, Snapshot
from ..protocol.errors import CommandError
from ..protocol.values import Value
from ..tags import Tag

_QUALITY_JSON = {Quality.GOOD: '"GOOD"', Quality.STALE: '"STALE"', Quality.ERROR: '"ERROR"'}
_GOOD_TAIL = ',"quality":"GOOD","timestamp":'
_dumps = json.dumps
_float_repr = float.__repr__


def _json_value(value: Value | None) -> str:
    """The JSON text of a tag value (floats JSON cannot carry as strings)."""
    if value.__class__ is float:
        if value - value == 0.0:  # finite (inf - inf and nan - nan are nan)
            return _float_repr(value)
        return '"NaN"' if value != value else ('"Infinity"' if value > 0 else '"-Infinity"')
    if value is None:
        return "null"
    if value is True:
        return "true"
    if value is False:
        return "false"
    if isinstance(value, int):
        return int.__repr__(value)
    return _dumps(value)


class ScanEncoder:
    """Builds the scan messages of one (PLC, group) as text, not through a dict per tag.

    Each tag's ``"name":{"value":...`` part is kept from the scan before while its value
    stays the same; in a scan where every tag was read, the tags share the scan's timestamp,
    so the message is the kept parts joined by that timestamp's text (formatted once).
    """

    __slots__ = ("_head", "_keys", "_parts", "_values")

    def __init__(self, plc: str, group: str) -> None:
        self._head = f'{{"plc":{_dumps(plc)},"group":{_dumps(group)},"scan":'
        #: tag name -> its ``"name":{"value":`` text.
        self._keys: dict[str, str] = {}
        #: The values ``_parts`` were built from (a scan in which every tag was read).
        self._values: dict[str, Value | None] | None = None
        self._parts: list[str] = []

    def _key(self, name: str) -> str:
        key = self._keys.get(name)
        if key is None:
            key = self._keys[name] = f'{_dumps(name)}:{{"value":'
        return key

    def encode(self, snap: Snapshot, names: Sequence[str] | None = None) -> bytes:
        """The JSON of ``snap`` with the readings of ``names`` (default: all)."""
        stamp = _float_repr(snap.timestamp)
        error = snap.error
        head = (
            f'{self._head}{snap.scan},"timestamp":{stamp},"duration":{snap.duration:.6f},'
            f'"error":{"null" if error is None else _dumps(error)},"values":{{'
        )
        readings = snap.readings
        if names is None and isinstance(readings, GoodReadings):
            return (head + stamp.join(self._good_parts(snap.values))).encode()
        if names is None:
            names = list(readings)
        stamps: dict[float, str] = {snap.timestamp: stamp}
        out = []
        for name in names:
            r = readings[name]
            t = r.timestamp
            if t is None:
                t_text = "null"
            else:
                t_text = stamps.get(t) or stamps.setdefault(t, _float_repr(t))
            text = (
                f"{self._key(name)}{_json_value(r.value)},"
                f'"quality":{_QUALITY_JSON[r.quality]},"timestamp":{t_text}'
            )
            if r.error is not None:
                text += f',"error":{_dumps(r.error)}'
            out.append(text)
        return (head + "},".join(out) + ("}}}" if out else "}}")).encode()

    def _good_parts(self, values: dict[str, Value | None]) -> list[str]:
        """The parts of an all-good scan's ``values`` object, to be joined by its timestamp;
        only the parts of tags whose value changed are made again."""
        parts = self._parts
        old = self._values
        if old is not None and values == old:
            return parts
        key = self._key
        if old is not None and len(old) == len(values):
            for i, ((was_name, was), (name, value)) in enumerate(
                zip(old.items(), values.items(), strict=True)
            ):
                if was_name != name:  # not the same tags in the same order: make all anew
                    break
                if not (was is value or was == value):
                    parts[i] = f"{'},' if i else ''}{key(name)}{_json_value(value)}{_GOOD_TAIL}"
            else:
                self._values = values
                return parts
        parts = self._parts = [
            f"{'},' if i else ''}{key(name)}{_json_value(value)}{_GOOD_TAIL}"
            for i, (name, value) in enumerate(values.items())
        ]
        parts.append("}}}" if values else "}}")
        self._values = values
        return parts


def scan_message(plc: str, group: str, snap: Snapshot, names: Sequence[str] | None = None) -> bytes:
    """The JSON of one scan, with the readings of ``names`` (default: all)."""
    return ScanEncoder(plc, group).encode(snap, names)


def status_message(state: str, **extra: Any) -> bytes:
    return json.dumps({"state": state, **extra}, separators=(",", ":")).encode()


#: Bytes a set payload may have (``max_payload``), by default; a larger one is refused
#: unread.
MAX_PAYLOAD = 65536
#: How deeply a set payload may nest: ``{"value": ...}`` around a scalar is depth 1.
MAX_DEPTH = 2
_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')
_BRACKET = re.compile(rb"[\[\]{}]")
#: Integer kinds' ranges (BCD: the digits the words hold).
INT_RANGES: dict[str, tuple[int, int]] = {
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
    "bcd16": (0, 9999),
    "bcd32": (0, 99_999_999),
}
#: The largest magnitude of each float kind.
FLOAT_MAX = {"float32": 3.4028234663852886e38, "float64": sys.float_info.max}


class SetPayloadError(CommandError):
    """A set payload that is not a value for its tag (nothing is written); ``request_id``
    is the payload's ``id`` where it could be read."""

    def __init__(self, message: str, request_id: str | None = None) -> None:
        super().__init__(message)
        self.request_id = request_id


def _depth_over(payload: bytes, limit: int) -> bool:
    """Whether ``payload`` nests arrays or objects deeper than ``limit`` (strings, which may
    hold brackets, are left out first): checked before ``json.loads``, which recurses."""
    depth = 0
    for m in _BRACKET.finditer(_STRING.sub(b"", payload)):
        if m.group() in b"[{":
            depth += 1
            if depth > limit:
                return True
        else:
            depth -= 1
    return False


class _NonFinite(ValueError):
    pass


def _constant(name: str) -> object:
    raise _NonFinite(f"{name} is not a finite number: refused")


def parse_set(payload: bytes, tag: Tag, *, max_size: int = MAX_PAYLOAD) -> tuple[Value, str | None]:
    """(value, request id) of a set payload, checked against the tag's type.

    The size is checked before anything is parsed, the nesting before ``json.loads``;
    ``NaN``, ``Infinity`` and numbers a float cannot hold are refused, and so is any number
    outside the tag type's range (the message gives the range). The error carries the
    payload's ``id`` whenever the payload is an object with a usable one.
    """
    if len(payload) > max_size:
        raise SetPayloadError(f"payload of {len(payload)} bytes: at most {max_size} (not read)")
    if _depth_over(payload, MAX_DEPTH):
        raise SetPayloadError(
            f'payload nests deeper than {MAX_DEPTH} levels: send a value or {{"value": ..., '
            '"id": ...}'
        )
    try:
        data = json.loads(payload.decode("utf-8"), parse_constant=_constant)
    except _NonFinite as exc:
        raise SetPayloadError(f"{tag.name}: {exc}") from None
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise SetPayloadError(f"payload is not JSON: {_cut(str(exc))}") from None
    request_id: str | None = None
    if isinstance(data, dict):
        raw_id = data.get("id")
        id_ok = raw_id is None or (isinstance(raw_id, (str, int)) and not isinstance(raw_id, bool))
        if id_ok and raw_id is not None:
            request_id = _cut(str(raw_id), 200)
        try:
            if not id_ok:
                raise SetPayloadError("id must be a string or a number")
            if "value" not in data:
                raise SetPayloadError('an object payload needs "value" (and may carry "id")')
            unknown = set(data) - {"value", "id"}
            if unknown:
                names = ", ".join(_cut(k, 40) for k in sorted(unknown)[:5])
                raise SetPayloadError(f"unknown key(s) {names}; use value and id")
            value = check_value(data["value"], tag)
        except SetPayloadError as exc:
            exc.request_id = request_id
            raise
        return value, request_id
    return check_value(data, tag), request_id


def _a(kind: str) -> str:
    return f"an {kind}" if kind.startswith("int") else f"a {kind}"


def request_id_of(payload: bytes, max_size: int = MAX_PAYLOAD) -> str | None:
    """The ``id`` of a set payload that is refused before its value is looked at (a tag
    that is not writable, a retained message), where it can be read safely; else None."""
    if len(payload) > max_size or _depth_over(payload, MAX_DEPTH):
        return None
    try:
        data = json.loads(payload.decode("utf-8"), parse_constant=_constant)
    except (UnicodeDecodeError, ValueError, RecursionError):
        return None
    if not isinstance(data, dict):
        return None
    raw_id = data.get("id")
    if isinstance(raw_id, (str, int)) and not isinstance(raw_id, bool):
        return _cut(str(raw_id), 200)
    return None


def _cut(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def _shown(data: object) -> str:
    """``repr(data)`` cut short: a refusal does not echo a large payload back."""
    return _cut(repr(data), 60)


def check_value(data: object, tag: Tag) -> Value:
    """``data`` as a value of ``tag``'s type, or :class:`SetPayloadError` saying why not."""
    vtype = tag.vtype
    kind = vtype.kind
    value: Value
    number = isinstance(data, (int, float)) and not isinstance(data, bool)
    if kind == "bit":
        if not isinstance(data, bool) and data not in (0, 1):
            raise SetPayloadError(
                f"{tag.name} is a bit: send true/false or 0/1, got {_shown(data)}"
            )
        value = bool(data)
    elif kind == "string":
        if not isinstance(data, str):
            raise SetPayloadError(
                f"{tag.name} is a {vtype}: send a JSON string, got {_shown(data)}"
            )
        value = data
    elif kind.startswith("float"):
        if not number:
            raise SetPayloadError(f"{tag.name} is {_a(kind)}: send a number, got {_shown(data)}")
        top = FLOAT_MAX.get(kind, sys.float_info.max)
        assert isinstance(data, (int, float))
        try:
            value = float(data)
        except OverflowError:  # an integer past 1.8e308
            value = math.inf
        if not math.isfinite(value) or abs(value) > top:
            raise SetPayloadError(
                f"{tag.name} is {_a(kind)}: {_shown(data)} is out of range "
                f"(a finite number in -{top:.8g}..{top:.8g})"
            )
    else:  # integers and BCD
        low, high = INT_RANGES.get(kind, (-(2**63), 2**64 - 1))
        if not number:
            raise SetPayloadError(
                f"{tag.name} is {_a(kind)}: send a whole number in {low}..{high}, "
                f"got {_shown(data)}"
            )
        assert isinstance(data, (int, float))
        if isinstance(data, float) and not math.isfinite(data):
            raise SetPayloadError(
                f"{tag.name} is {_a(kind)}: {_shown(data)} is out of range {low}..{high}"
            )
        if not low <= data <= high:
            raise SetPayloadError(
                f"{tag.name} is {_a(kind)}: {_shown(data)} is out of range {low}..{high}"
            )
        if not isinstance(data, int):
            raise SetPayloadError(
                f"{tag.name} is {_a(kind)}: send a whole number in {low}..{high}, "
                f"got {_shown(data)}"
            )
        value = data
    try:
        vtype.encode(value)  # range, length and encoding
    except CommandError as exc:
        raise SetPayloadError(f"{tag.name}: {_cut(str(exc))}") from None
    return value
