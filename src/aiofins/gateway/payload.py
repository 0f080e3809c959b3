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
from collections.abc import Iterable
from typing import Any

from ..poller import Snapshot, TagReading
from ..protocol.errors import CommandError
from ..protocol.values import Value
from ..tags import Tag

_QUALITY = {"good": "GOOD", "stale": "STALE", "error": "ERROR"}


def _json_value(value: Value | None) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    return value


def _reading(r: TagReading) -> dict[str, Any]:
    out: dict[str, Any] = {
        "value": _json_value(r.value),
        "quality": _QUALITY[r.quality.value],
        "timestamp": r.timestamp,
    }
    if r.error is not None:
        out["error"] = r.error
    return out


def scan_message(plc: str, group: str, snap: Snapshot, names: Iterable[str]) -> bytes:
    """The JSON of one scan, with the readings of ``names``."""
    readings = snap.readings
    return json.dumps(
        {
            "plc": plc,
            "group": group,
            "scan": snap.scan,
            "timestamp": snap.timestamp,
            "duration": round(snap.duration, 6),
            "error": snap.error,
            "values": {name: _reading(readings[name]) for name in names},
        },
        allow_nan=False,
        separators=(",", ":"),
    ).encode()


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
