"""Event hooks: the container, its cheapness when empty, and its boundary around callbacks."""

from __future__ import annotations

import dataclasses
import logging

import pytest

import aiofins
from aiofins.hooks import (
    ConnectionStateChanged,
    EventHooks,
    RequestRetried,
    RequestSent,
    RequestTimedOut,
    ResponseReceived,
    ScanDone,
)
from aiofins.protocol.header import FinsAddress

DEST = FinsAddress(0, 1, 0)


def test_exported_from_aiofins() -> None:
    for name in (
        "EventHooks",
        "RequestSent",
        "ResponseReceived",
        "RequestRetried",
        "RequestTimedOut",
        "ConnectionStateChanged",
        "ScanDone",
    ):
        assert getattr(aiofins, name) is getattr(aiofins.hooks, name)


def test_events_are_frozen_and_slotted() -> None:
    event = ResponseReceived("udp://h:9600", DEST, 7, 0x0101, 0x0000, 0.001, 1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        event.sid = 8  # type: ignore[misc]
    assert not hasattr(event, "__dict__")
    assert event == ResponseReceived("udp://h:9600", DEST, 7, 0x0101, 0, 0.001, 1)


def test_empty_hooks_are_none_for_emitters() -> None:
    assert not EventHooks()
    assert EventHooks().or_none() is None
    hooks = EventHooks(scan_done=[print])
    assert hooks.or_none() is hooks


def test_emit_calls_each_callback_in_order() -> None:
    seen: list[tuple[str, object]] = []
    hooks = EventHooks()
    hooks.request_sent.append(lambda e: seen.append(("a", e)))
    hooks.request_sent.append(lambda e: seen.append(("b", e)))
    event = RequestSent("udp://h:9600", DEST, 3, 0x0101)
    hooks.emit(hooks.request_sent, event)
    assert seen == [("a", event), ("b", event)]


def test_a_raising_hook_is_logged_counted_and_skipped(caplog: pytest.LogCaptureFixture) -> None:
    seen: list[object] = []

    def broken(event: object) -> None:
        raise RuntimeError("hook bug")

    hooks = EventHooks(request_timed_out=[broken, seen.append])
    event = RequestTimedOut("udp://h:9600", DEST, 3, 0x0101, 3, 2.0)
    with caplog.at_level(logging.ERROR, logger="aiofins.hooks"):
        hooks.emit(hooks.request_timed_out, event)
        hooks.emit(hooks.request_timed_out, event)
    assert seen == [event, event]
    assert hooks.errors == 2
    records = [r for r in caplog.records if r.name == "aiofins.hooks"]
    assert len(records) == 2
    assert "RequestTimedOut" in records[0].getMessage()
    assert records[0].exc_info is not None


def test_every_event_type_has_its_list() -> None:
    hooks = EventHooks()
    pairs: list[tuple[list[object], object]] = [
        (hooks.request_sent, RequestSent("e", DEST, 1, 0x0101)),  # type: ignore[list-item]
        (hooks.response_received, ResponseReceived("e", DEST, 1, 0x0101, 0, 0.0, 1)),  # type: ignore[list-item]
        (hooks.request_retried, RequestRetried("e", DEST, 1, 0x0101, 2, 0.01)),  # type: ignore[list-item]
        (hooks.request_timed_out, RequestTimedOut("e", DEST, 1, 0x0101, 3, 1.0)),  # type: ignore[list-item]
        (hooks.connection_state_changed, ConnectionStateChanged("e", "CLOSED", "OPEN")),  # type: ignore[list-item]
        (hooks.scan_done, ScanDone("fast", 1, 0.002, 0)),  # type: ignore[list-item]
    ]
    for callbacks, event in pairs:
        seen: list[object] = []
        callbacks.append(seen.append)
        assert hooks
        hooks.emit(callbacks, event)  # type: ignore[arg-type]
        assert seen == [event]


def test_combined_hooks_call_each_set_in_turn() -> None:
    calls: list[str] = []
    first = EventHooks(request_sent=[lambda e: calls.append("first")])
    second = EventHooks(
        request_sent=[lambda e: calls.append("second")], scan_done=[lambda e: calls.append("scan")]
    )
    both = EventHooks.combine(first, second)
    both.emit(both.request_sent, RequestSent("udp://h:9600", DEST, 1, 0x0101))
    both.emit(both.scan_done, ScanDone("g", 1, 0.01, 0))
    assert calls == ["first", "second", "scan"]
    assert not EventHooks.combine(EventHooks(), EventHooks())
