"""Scan messages and set payloads (no broker needed), and the outbox bound."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.gateway.config import MqttConfig
from aiofins.gateway.mqtt import MqttLink
from aiofins.gateway.payload import ScanEncoder, SetPayloadError, parse_set, scan_message
from aiofins.poller import GoodReadings, Quality, Snapshot, TagReading
from aiofins.protocol.values import Value
from aiofins.tags import parse_tag


def test_scan_message_carries_values_qualities_and_json_safe_floats() -> None:
    snap = Snapshot(
        "p/g",
        "udp://x",
        7,
        100.5,
        0.0021,
        {
            "a": TagReading(1.5, Quality.GOOD, 100.5),
            "b": TagReading(math.nan, Quality.STALE, 99.5, "FinsTimeout: no reply"),
            "c": TagReading(None, Quality.ERROR, None, "bad"),
            "d": TagReading(-math.inf, Quality.GOOD, 100.5),
        },
        frozenset({"a"}),
    )
    doc = json.loads(scan_message("p", "g", snap, ["a", "b", "c", "d"]))
    assert doc == {
        "plc": "p",
        "group": "g",
        "scan": 7,
        "timestamp": 100.5,
        "duration": 0.0021,
        "error": None,
        "values": {
            "a": {"value": 1.5, "quality": "GOOD", "timestamp": 100.5},
            "b": {
                "value": "NaN",
                "quality": "STALE",
                "timestamp": 99.5,
                "error": "FinsTimeout: no reply",
            },
            "c": {"value": None, "quality": "ERROR", "timestamp": None, "error": "bad"},
            "d": {"value": "-Infinity", "quality": "GOOD", "timestamp": 100.5},
        },
    }
    assert json.loads(scan_message("p", "g", snap, ["a"]))["values"].keys() == {"a"}


def _expected(value: Value | None) -> object:
    if isinstance(value, float) and math.isnan(value):
        return "NaN"
    if isinstance(value, float) and math.isinf(value):
        return "Infinity" if value > 0 else "-Infinity"
    return value


_TAG_VALUES = st.fixed_dictionaries(
    {
        "count": st.integers(-(2**63), 2**64),
        "level": st.floats(allow_nan=True, allow_infinity=True, width=32),
        "temp": st.floats(allow_nan=True, allow_infinity=True),
        "run": st.booleans(),
        'na"me\\ü': st.text(max_size=8),
    }
)


@given(
    scans=st.lists(
        st.tuples(_TAG_VALUES, st.floats(0, 2e9), st.floats(0, 10), st.booleans()),
        min_size=1,
        max_size=6,
    )
)
def test_an_encoder_gives_the_json_of_every_scan_in_a_row(
    scans: list[tuple[dict[str, Value], float, float, bool]],
) -> None:
    """One encoder over a run of scans (all-good ones reuse the parts of unchanged tags,
    some failed in between) gives each scan's exact JSON."""
    encoder = ScanEncoder('pl"c', "g")
    last: dict[str, Value] = {}
    for scan, (values, stamp, duration, failed) in enumerate(scans):
        if failed:  # stale values with the last scan's timestamp
            readings: Mapping[str, TagReading] = {
                name: TagReading(last.get(name), Quality.STALE, 1.5, "FinsTimeout: x")
                for name in values
            }
            error: str | None = "FinsTimeout: x"
            expected = {
                name: {
                    "value": _expected(last.get(name)),
                    "quality": "STALE",
                    "timestamp": 1.5,
                    "error": "FinsTimeout: x",
                }
                for name in values
            }
        else:
            readings, error, last = GoodReadings(dict(values), stamp), None, values
            expected = {
                name: {"value": _expected(v), "quality": "GOOD", "timestamp": stamp}
                for name, v in values.items()
            }
        snap = Snapshot("p/g", "udp://x", scan, stamp, duration, readings, frozenset(), error)
        doc = json.loads(encoder.encode(snap))
        assert doc.pop("duration") == pytest.approx(duration, abs=1e-6)
        assert doc == {
            "plc": 'pl"c',
            "group": "g",
            "scan": scan,
            "timestamp": stamp,
            "error": error,
            "values": expected,
        }
        assert json.loads(encoder.encode(snap, ["run"]))["values"] == {"run": expected["run"]}


@pytest.mark.parametrize(
    ("spec", "payload", "value"),
    [
        ("D0:int16", b"-5", -5),
        ("D0:uint32", b'{"value": 70000, "id": 9}', 70000),
        ("D0:float32", b"2", 2.0),
        ("D0:float64", b"-1.25", -1.25),
        ("CIO 0.01", b"true", True),
        ("CIO 0.01", b"0", False),
        ("D0:bcd16", b"1234", 1234),
        ("D0:string:4", b'"AB"', "AB"),
    ],
)
def test_set_payloads_of_each_type(spec: str, payload: bytes, value: object) -> None:
    got, request_id = parse_set(payload, parse_tag("t", spec))
    assert got == value and type(got) is type(value)
    assert request_id == ("9" if b"id" in payload else None)


@pytest.mark.parametrize(
    ("spec", "payload", "why"),
    [
        ("D0:int16", b"", "not JSON"),
        ("D0:int16", b"\xff\xfe", "not JSON"),
        ("D0:int16", b"40000", "t is an int16: 40000 is out of range -32768..32767"),
        ("D0:int16", b"1.0", "whole number"),
        ("D0:int16", b"null", "whole number"),
        ("D0:uint16", b"-1", "out of range 0..65535"),
        ("D0:float32", b"true", "send a number"),
        ("D0:float32", b'"1"', "send a number"),
        ("CIO 0.01", b"2", "bit"),
        ("D0:bcd16", b"10000", "t is a bcd16: 10000 is out of range 0..9999"),
        ("D0:int16", b"1e9", "t is an int16: 1000000000.0 is out of range -32768..32767"),
        ("D0:int16", b"1.5", "send a whole number in -32768..32767, got 1.5"),
        ("D0:float32", b"NaN", "t: NaN is not a finite number"),
        ("D0:float32", b"-Infinity", "t: -Infinity is not a finite number"),
        ("D0:float64", b"1e400", "t is a float64: inf is out of range"),
        (
            "D0:float32",
            b"3.5e38",
            "out of range (a finite number in -3.4028235e+38..3.4028235e+38)",
        ),
        ("D0:float32", b"1" + b"0" * 400, "out of range"),
        ("D0:int16", b"[" * 100_000 + b"]" * 100_000, "at most 65536 (not read)"),
        ("D0:int16", b"[" * 30_000 + b"]" * 30_000, "nests deeper than 2 levels"),
        ("D0:int16", b'{"value": [[1]], "id": "x"}', "nests deeper"),
        ("D0:string:4", b'"' + b"x" * 60_000 + b'"', "is 60000 bytes, longer than 4"),
        ("D0:string:2", b'"ABC"', "t:"),
        ("D0:string:2", b"5", "JSON string"),
        ("D0:int16", b'{"id": 1}', '"value"'),
        ("D0:int16", b'{"value": 1, "id": [1]}', "id must be"),
        ("D0:int16", b'{"value": 1, "x": 1}', "unknown key"),
    ],
)
def test_bad_set_payloads_say_why(spec: str, payload: bytes, why: str) -> None:
    with pytest.raises(SetPayloadError, match=None) as info:
        parse_set(payload, parse_tag("t", spec))
    assert why in str(info.value)


@pytest.mark.anyio
async def test_a_full_outbox_drops_its_oldest_but_not_the_one_being_sent(
    anyio_backend: object,
) -> None:
    link = MqttLink(MqttConfig(), client_id="x", status_topic="s")
    box = link.outbox("t", limit=3)
    for i in range(5):
        link.put(box, b"%d" % i, 0.0)
    assert [p for p, _ in box.messages] == [b"2", b"3", b"4"] and box.dropped == 2
    box.sending = box.messages[0]
    link.put(box, b"5", 0.0)
    assert [p for p, _ in box.messages] == [b"2", b"4", b"5"] and box.dropped == 3
    one = link.outbox("one", limit=1)
    link.put(one, b"a", 0.0)
    one.sending = one.messages[0]
    link.put(one, b"b", 0.0)  # the one being sent stays; the new one waits behind it
    link.put(one, b"c", 0.0)
    assert [p for p, _ in one.messages] == [b"a", b"c"] and one.dropped == 1
    assert link.queued_messages == 5 and link.dropped == 4


def test_a_refusal_echoes_the_id_and_not_the_payload() -> None:
    """``{"value": "abc", "id": "B"}`` was answered with ``"id": null``; a 60 kB string
    value was echoed whole into the refusal."""
    sp = parse_tag("sp", "D0:int16")
    with pytest.raises(SetPayloadError) as info:
        parse_set(b'{"value": "abc", "id": "B"}', sp)
    assert info.value.request_id == "B"
    with pytest.raises(SetPayloadError) as info:
        parse_set(b'{"value": "' + b"x" * 60_000 + b'", "id": 7}', sp)
    assert info.value.request_id == "7" and len(str(info.value)) < 200
    with pytest.raises(SetPayloadError) as info:
        parse_set(b'{"value": 1, "id": 2, "' + b"k" * 50_000 + b'": 0}', sp)
    assert info.value.request_id == "2" and len(str(info.value)) < 200
