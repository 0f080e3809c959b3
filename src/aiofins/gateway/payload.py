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


class SetPayloadError(CommandError):
    """A set payload that is not a value for its tag (nothing is written)."""


def parse_set(payload: bytes, tag: Tag) -> tuple[Value, str | None]:
    """(value, request id) of a set payload, checked against the tag's type."""
    try:
        data = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise SetPayloadError(f"payload is not JSON: {exc}") from None
    request_id: str | None = None
    if isinstance(data, dict):
        if "value" not in data:
            raise SetPayloadError('an object payload needs "value" (and may carry "id")')
        unknown = set(data) - {"value", "id"}
        if unknown:
            raise SetPayloadError(f"unknown key(s) {', '.join(sorted(unknown))}; use value and id")
        raw_id = data.get("id")
        if raw_id is not None and not isinstance(raw_id, (str, int)):
            raise SetPayloadError("id must be a string or a number")
        request_id = None if raw_id is None else str(raw_id)
        data = data["value"]
    return check_value(data, tag), request_id


def check_value(data: object, tag: Tag) -> Value:
    """``data`` as a value of ``tag``'s type, or :class:`SetPayloadError` saying why not."""
    vtype = tag.vtype
    kind = vtype.kind
    value: Value
    if kind == "bit":
        if not isinstance(data, bool) and data not in (0, 1):
            raise SetPayloadError(f"{tag.name} is a bit: send true/false or 0/1, got {data!r}")
        value = bool(data)
    elif kind == "string":
        if not isinstance(data, str):
            raise SetPayloadError(f"{tag.name} is a {vtype}: send a JSON string, got {data!r}")
        value = data
    elif kind.startswith("float"):
        if isinstance(data, bool) or not isinstance(data, (int, float)):
            raise SetPayloadError(f"{tag.name} is a {kind}: send a number, got {data!r}")
        value = float(data)
    else:  # integers and BCD
        if isinstance(data, bool) or not isinstance(data, int):
            raise SetPayloadError(f"{tag.name} is a {kind}: send a whole number, got {data!r}")
        value = data
    try:
        vtype.encode(value)  # range, length and encoding
    except CommandError as exc:
        raise SetPayloadError(f"{tag.name}: {exc}") from None
    return value
