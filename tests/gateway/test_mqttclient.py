"""The gateway's MQTT connection (paho-mqtt on the event loop) and its bounded inbox."""

from __future__ import annotations

import logging

import anyio
import pytest

from aiofins.gateway.mqttclient import (
    DROPS_LOGGED_EVERY,
    ConnectionLost,
    ConnectSettings,
    Inbox,
    MqttConnection,
    Received,
)

from .conftest import HANG, Broker, free_port, publisher

pytestmark = pytest.mark.anyio


def message(at: float, size: int = 10, topic: str = "t") -> Received:
    return Received(topic, b"x" * size, False, None, at)


async def test_the_inbox_is_bounded_in_messages_and_bytes_and_counts_what_it_drops(
    anyio_backend: object, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, "aiofins.gateway")
    inbox = Inbox(limit=3, max_bytes=100)
    assert [inbox.put(message(0.0)) for _ in range(4)] == [True, True, True, False]
    assert (len(inbox.messages), inbox.size, inbox.dropped, inbox.dropped_bytes) == (3, 30, 1, 10)
    assert (await inbox.get()).payload == b"x" * 10
    assert not inbox.put(message(1.0, size=81))  # 20 + 81 > 100 bytes
    assert inbox.put(message(2.0, size=80))  # 20 + 80 = 100: fits
    assert (inbox.dropped, inbox.dropped_bytes, inbox.size) == (2, 91, 100)
    # One line at the first drop, then at most one per DROPS_LOGGED_EVERY, with the count.
    assert not inbox.put(message(DROPS_LOGGED_EVERY - 0.5))
    assert not inbox.put(message(DROPS_LOGGED_EVERY, topic="last"))
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2, lines
    assert lines[0].startswith("received MQTT messages dropped: 1 (the last on t, 10 bytes): ")
    assert lines[1].startswith("received MQTT messages dropped: 3 (the last on last, 10 bytes)")
    assert (
        "3 messages of 100 bytes wait for the gateway already (at most 3 messages, 100 "
        in (lines[1])
    )
    assert lines[1].endswith("; 4 dropped since the start")


async def test_a_get_waits_for_the_next_message(anyio_backend: object) -> None:
    inbox = Inbox()
    got: list[Received] = []
    async with anyio.create_task_group() as tg:

        async def take() -> None:
            got.append(await inbox.get())

        tg.start_soon(take)
        await anyio.wait_all_tasks_blocked()
        assert got == []
        inbox.put(message(0.0))
    assert [m.payload for m in got] == [b"x" * 10] and inbox.size == 0


async def test_publish_subscribe_and_receive_on_a_real_broker(broker: Broker) -> None:
    for protocol in ("5", "3.1.1"):
        inbox = Inbox()
        settings = ConnectSettings("127.0.0.1", broker.port, f"c{protocol}", protocol=protocol)
        conn = MqttConnection(settings, inbox)
        await conn.connect()
        await conn.subscribe("in/#", qos=1)
        await conn.publish("in/self", b"one", qos=1, retain=False)
        info = conn.publish_now("in/self", b"two", retain=False)
        assert info.rc == 0 and info.is_published()  # written before publish_now returned
        async with publisher(broker.port) as pub:
            await pub.publish("in/other", b"three", qos=1)
        with anyio.fail_after(HANG):
            got = [await inbox.get() for _ in range(3)]
        assert sorted((m.topic, m.payload) for m in got) == [
            ("in/other", b"three"),
            ("in/self", b"one"),
            ("in/self", b"two"),
        ]
        await conn.disconnect()
        assert conn.lost is not None and conn.lost.startswith("disconnected")
        with pytest.raises(ConnectionLost):
            await conn.publish("in/self", b"late", qos=1, retain=False)


async def test_a_refused_connection_says_why(anyio_backend: object) -> None:
    settings = ConnectSettings("127.0.0.1", free_port(), "nobody-listens", timeout=5)
    conn = MqttConnection(settings, Inbox())
    with pytest.raises(ConnectionLost, match="refused"):
        await conn.connect()
    assert not conn.connected and conn.closed.is_set()
