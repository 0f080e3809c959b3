"""Write-back as a protocol, against a real Mosquitto and virtual PLCs: retained sets, age,
the per-PLC queue, payload size and nesting, values, one reply per request with its id, and
the bounded pool of reply outboxes (docs/gateway.md, "Writing back")."""

from __future__ import annotations

import json
from pathlib import Path

import anyio
import pytest
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from aiofins.gateway import Gateway
from aiofins.gateway.config import parse_config
from aiofins.gateway.mqttclient import MAX_INCOMING_BYTES
from aiofins.gateway.writes import REPLY_POOL
from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.simulator.faults import Delay, FaultRule

from .conftest import Broker, eventually, need_mosquitto, publisher, subscribe
from .test_daemon import config

pytestmark = pytest.mark.anyio


@pytest.fixture
def anyio_backend() -> str:
    """The gateway on stock asyncio only: these floods cost seconds each, and the event
    loop does not change what they check (test_daemon runs uvloop too)."""
    return "asyncio"


SET = "fins/p1/w/set"


def group(port: int, extra: str = "", gateway: str = "") -> str:
    return f"""
{gateway}
[[groups]]
name = "w"
interval = 0.5
tags = {{ sp = "D120:int16", level = "D130:float32", ro = "D140" }}
writable = ["sp", "level"]
{extra}
[[plcs]]
name = "p1"
url = "udp://127.0.0.1:{port}"
"""


async def test_nested_huge_and_non_finite_payloads_are_refused_and_the_gateway_lives(
    broker: Broker,
) -> None:
    """A 200 kB nested payload raised RecursionError out of the parser and ended the
    gateway; a 20 MB one was parsed and echoed; NaN, Infinity and 1e400 were written."""
    plc = VirtualPLC()
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        cfg = config(broker, group(sim.udp_port))
        async with (
            subscribe(broker.port, f"{SET}/+/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()
            cases = [
                ("sp", b"[" * 100_000 + b"]" * 100_000, "at most 65536 (not read)"),
                ("sp", b"[" * 30_000 + b"]" * 30_000, "nests deeper than 2 levels"),
                ("sp", b'{"value": {"value": {"value": 1}}, "id": "n"}', "nests deeper"),
                ("level", b"NaN", "NaN is not a finite number"),
                ("level", b'{"value": Infinity, "id": "i"}', "Infinity is not a finite"),
                ("level", b"1e400", "out of range (a finite number in -3.4028235e+38"),
                ("level", b"-3.5e38", "out of range"),
                ("sp", b"1e9", "1000000000.0 is out of range -32768..32767"),
            ]
            for tag, payload, _ in cases:
                await pub.publish(f"{SET}/{tag}", payload, qos=1)
            # 20 MB: over the maximum packet size the gateway tells the broker (MQTT 5), so
            # the broker drops it: it never reaches (or costs) the gateway.
            await pub.publish(f"{SET}/sp", b"1" * 20_000_000, qos=1)
            await pub.publish(f"{SET}/sp", b'{"value": 42, "id": "after"}', qos=1)
            await sub.wait_for(lambda: any(m["id"] == "after" for m in sub.on(f"{SET}/sp/reply")))
            # (the two reply topics are two outboxes: no order between them)
            await sub.wait_for(lambda: len(sub.on(f"{SET}/level/reply")) == 4)
            replies = sub.on(f"{SET}/sp/reply") + sub.on(f"{SET}/level/reply")
            assert len(replies) == len(cases) + 1, (
                gateway.write_counts,
                [(r["tag"], r["id"], (r["error"] or "")[:50]) for r in replies],
            )
            for _, _, why in cases:
                assert sum(why in (r["error"] or "") for r in replies) >= 1, (why, replies)
            assert all(len(json.dumps(r)) < 600 for r in replies)  # nothing echoed whole
            assert plc.read_value("D120", "int16") == 42
            assert plc.read_value("D130", "float32") == 0.0
            assert gateway.write_counts == {"invalid": len(cases), "written": 1}
            assert gateway.link.connects == 1 and gateway.link.disconnects == 0


async def test_retained_sets_are_refused_on_start_and_not_again_on_reconnect(
    tmp_path: Path,
) -> None:
    """A retained set message was written on every gateway start and broker reconnect."""
    need_mosquitto()
    broker = Broker(tmp_path, persistence=True)
    await anyio.to_thread.run_sync(broker.start)
    try:
        plc = VirtualPLC()
        async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
            async with publisher(broker.port) as pub:
                await pub.publish(f"{SET}/sp", '{"value": 5, "id": "old"}', qos=1, retain=True)
            cfg = config(broker, group(sim.udp_port))
            async with Gateway(cfg) as gateway:
                async with subscribe(broker.port, f"{SET}/sp/reply") as sub:
                    await sub.wait_for(lambda: sub.messages)
                    (reply,) = sub.on(f"{SET}/sp/reply")
                    assert reply["id"] == "old" and reply["ok"] is False
                    assert "retained set message is not written" in reply["error"]
                    # Published retained while the gateway listens: refused too (MQTT 5
                    # keeps the flag: the subscription asks for retain-as-published).
                    async with publisher(broker.port) as pub:
                        await pub.publish(
                            f"{SET}/sp", '{"value": 7, "id": "live"}', qos=1, retain=True
                        )
                    await sub.wait_for(lambda: len(sub.messages) == 2)
                    live = sub.on(f"{SET}/sp/reply")[1]
                    assert live["id"] == "live" and live["ok"] is False
                await anyio.to_thread.run_sync(broker.stop)
                await anyio.to_thread.run_sync(broker.start)
                async with subscribe(broker.port, f"{SET}/sp/reply") as sub:
                    await eventually(lambda: gateway.write_counts.get("retained", 0) >= 3)
                    # The retained one came again and was not answered again: a request
                    # after it is the next reply on the topic (replies keep their order).
                    async with publisher(broker.port) as pub:
                        await pub.publish(f"{SET}/sp", '{"value": 6, "id": "new"}', qos=1)
                    await sub.wait_for(lambda: sub.messages)
                    assert [r["id"] for r in sub.on(f"{SET}/sp/reply")] == ["new"]
                assert gateway.link.connects == 2
                assert gateway.write_counts == {"retained": 3, "written": 1}
            assert plc.read_value("D120", "int16") == 6
    finally:
        broker.stop()


async def test_one_reply_per_request_with_its_id(broker: Broker) -> None:
    """20 pairs of (valid, invalid) gave 42 replies; a refusal answered ``"id": null``."""
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
        cfg = config(broker, group(sim.udp_port))
        async with (
            subscribe(broker.port, f"{SET}/+/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()
            for i in range(20):
                await pub.publish(f"{SET}/sp", json.dumps({"value": i, "id": f"v{i}"}), qos=1)
                await pub.publish(f"{SET}/sp", json.dumps({"value": "abc", "id": f"b{i}"}), qos=1)
            await pub.publish(f"{SET}/ro", '{"value": 1, "id": "ro"}', qos=1)
            await pub.publish(f"{SET}/nope", '{"value": 1, "id": 7}', qos=1)
            await pub.publish(f"{SET}/sp", '{"value": 99, "id": "last"}', qos=1)
            await sub.wait_for(lambda: any(m["id"] == "last" for m in sub.on(f"{SET}/sp/reply")))
            await sub.wait_for(lambda: sub.on(f"{SET}/ro/reply") and sub.on(f"{SET}/nope/reply"))
            ids = [m["id"] for m in sub.on(f"{SET}/sp/reply")]
            assert sorted(ids) == sorted(
                [f"v{i}" for i in range(20)] + [f"b{i}" for i in range(20)] + ["last"]
            )
            for m in sub.on(f"{SET}/sp/reply"):
                assert m["ok"] is m["id"].startswith(("v", "last")), m
                if m["id"].startswith("b"):
                    assert "send a whole number in -32768..32767, got 'abc'" in m["error"]
            assert [m["id"] for m in sub.on(f"{SET}/ro/reply")] == ["ro"]
            assert "not writable" in sub.on(f"{SET}/ro/reply")[0]["error"]
            assert [m["id"] for m in sub.on(f"{SET}/nope/reply")] == ["7"]
            assert gateway.write_counts == {"written": 21, "invalid": 20, "refused": 2}


async def test_a_burst_is_bounded_by_the_queue_and_nothing_is_written_past_its_age(
    broker: Broker,
) -> None:
    """5,000 set requests against a PLC answering in 50 ms: ~1,500 were written 5-8 s after
    they were published and the rest later; replies past 100 per topic were dropped."""
    plc = VirtualPLC()
    max_age = 1.0
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        sim.plan.per_command[0x0102] = FaultRule(delay=Delay(0.05, 0.05))
        cfg = config(
            broker, group(sim.udp_port, f"write_max_age = {max_age}\ntimeout = 2"), timeout=2
        )
        count = 5000
        async with (
            subscribe(broker.port, f"{SET}/sp/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()
            for i in range(count):
                await pub.publish(f"{SET}/sp", json.dumps({"value": i, "id": str(i)}), qos=1)
            await sub.wait_for(lambda: len(sub.messages) >= count, timeout=120)
            replies = sub.on(f"{SET}/sp/reply")
            assert sorted(int(r["id"]) for r in replies) == list(range(count))  # each once
            written = [r for r in replies if r["ok"]]
            outcomes = dict(gateway.write_counts)
            assert outcomes.keys() <= {"written", "expired", "busy"}
            assert sum(outcomes.values()) == count and len(written) == outcomes["written"]
            assert outcomes["busy"] > 0 and outcomes["expired"] > 0  # the queue is bounded
            assert all(0 <= r["waited"] <= max_age for r in written)
            assert all(
                "expired" in r["error"] for r in replies if r["error"] and "s after" in r["error"]
            )
            # The PLC holds the last value written (the writes went in order).
            last = max(written, key=lambda r: int(r["id"]))
            assert plc.read_value("D120", "int16") == int(last["id"])
            assert gateway.link.outboxes[f"{SET}/sp/reply"].dropped == 0


async def test_invented_tag_names_cannot_grow_memory(broker: Broker) -> None:
    """A set on an invented tag name kept a reply outbox for ever (~22 MB per 20,000)."""
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
        cfg = config(broker, group(sim.udp_port))
        count = 20_000
        async with (
            subscribe(broker.port, f"{SET}/+/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()
            for i in range(count):
                # QoS 0: the broker passes them on as fast as they come.
                await pub.publish(f"{SET}/invented{i}", json.dumps({"value": 1, "id": i}), qos=0)
                assert len(gateway.reply_pool) <= REPLY_POOL
            await pub.publish(f"{SET}/sp", '{"value": 1, "id": "end"}', qos=1)
            pool, inbox = gateway.reply_pool, gateway.link.inbox
            # A request is answered, or its reply dropped for want of an outbox, or it was
            # dropped on arrival by a full inbox (a busy machine): each counted.
            await sub.wait_for(
                lambda: len(sub.messages) + pool.dropped + inbox.dropped >= count + 1, timeout=60
            )
            assert not [t for t in gateway.link.outboxes if "invented" in t]  # none made
            assert len(pool) <= REPLY_POOL
            answered = {m.json()["id"] for m in sub.messages} - {"end"}
            assert len(answered) == len(sub.messages) - 1  # no request answered twice
            assert len(answered) + pool.dropped + inbox.dropped == count
            refused = count - inbox.dropped
            assert gateway.write_counts == {"refused": refused, "written": 1}


async def test_an_mqtt5_message_expiry_shortens_the_age(broker: Broker) -> None:
    """A request whose MQTT 5 expiry passes while it waits in the queue is refused
    "expired", not written."""
    plc = VirtualPLC()
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        sim.plan.per_command[0x0102] = FaultRule(delay=Delay(1.5, 1.5))
        cfg = config(broker, group(sim.udp_port, "timeout = 5"), timeout=5)
        async with (
            subscribe(broker.port, f"{SET}/sp/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()
            await pub.publish(f"{SET}/sp", '{"value": 1, "id": "first"}', qos=1)
            expiring = Properties(PacketTypes.PUBLISH)  # type: ignore[no-untyped-call]
            expiring.MessageExpiryInterval = 1
            await pub.publish(
                f"{SET}/sp", '{"value": 2, "id": "short"}', qos=1, properties=expiring
            )
            await sub.wait_for(lambda: len(sub.messages) == 2)
            first, short = sub.on(f"{SET}/sp/reply")
            assert first["ok"] is True and short["id"] == "short" and short["ok"] is False
            assert "expired" in short["error"]
            assert plc.read_value("D120", "int16") == 1
            assert gateway.write_counts == {"written": 1, "expired": 1}


async def test_mqtt_3_1_1_still_publishes_and_writes(broker: Broker) -> None:
    """``protocol = "3.1.1"`` for brokers without MQTT 5: no expiry, no maximum packet size,
    and a retained set published while the gateway listens arrives without its flag (3.1.1
    clears it), so only its replays are refused (docs/gateway.md)."""
    plc = VirtualPLC()
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        cfg = parse_config(
            f"""
[gateway]
name = "gw"
[mqtt]
port = {broker.port}
protocol = "3.1.1"
[http]
enabled = false
"""
            + group(sim.udp_port),
            "t.toml",
        )
        async with (
            subscribe(broker.port, "fins/p1/w", f"{SET}/sp/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()
            await pub.publish(f"{SET}/sp", '{"value": 9, "id": "a"}', qos=1)
            await pub.publish(f"{SET}/sp", "[[[1]]]", qos=1)
            await sub.wait_for(lambda: len(sub.on(f"{SET}/sp/reply")) == 2 and sub.on("fins/p1/w"))
            # The refusal is answered at once, the write when the PLC has taken it: either
            # reply may come first.
            replies = sub.on(f"{SET}/sp/reply")
            (ok,) = [r for r in replies if r["id"] == "a"]
            (nested,) = [r for r in replies if r is not ok]
            assert ok["ok"] is True and nested["ok"] is False
            assert "nests deeper" in nested["error"]
            assert plc.read_value("D120", "int16") == 9
            assert gateway.write_counts == {"written": 1, "invalid": 1}


async def test_huge_payloads_over_mqtt_3_1_1_are_bounded_by_the_inbox(
    broker: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    """MQTT 3.1.1 has no maximum packet size: the broker sends a message whole, and paho
    reads it whole. One up to the inbox's byte bound is refused unread, answered; one over
    it is dropped, counted and logged, unanswered; the gateway goes on."""
    plc = VirtualPLC()
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        cfg = parse_config(
            f'[gateway]\nname = "gw"\n[mqtt]\nport = {broker.port}\nprotocol = "3.1.1"\n'
            "[http]\nenabled = false\n" + group(sim.udp_port),
            "t.toml",
        )
        async with (
            subscribe(broker.port, f"{SET}/sp/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()
            over = MAX_INCOMING_BYTES + 1
            await pub.publish(f"{SET}/sp", b"1" * 1_000_000, qos=1)
            await pub.publish(f"{SET}/sp", b"2" * over, qos=1)
            await pub.publish(f"{SET}/sp", b'{"value": 43, "id": "after"}', qos=1)
            await sub.wait_for(lambda: any(m["id"] == "after" for m in sub.on(f"{SET}/sp/reply")))
            big, after = sub.on(f"{SET}/sp/reply")
            assert big["error"].endswith("payload of 1000000 bytes: at most 65536 (not read)")
            assert after["ok"] is True and plc.read_value("D120", "int16") == 43
            inbox = gateway.link.inbox
            assert (inbox.dropped, inbox.dropped_bytes) == (1, over)
            assert gateway.write_counts == {"invalid": 1, "written": 1}
            assert gateway.link.connects == 1 and gateway.link.disconnects == 0
            (line,) = [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()]
            assert line.startswith(f"received MQTT messages dropped: 1 (the last on {SET}/sp, ")
            assert f"{over} bytes" in line
            text = gateway.metrics.render().decode()
            assert "aiofins_gateway_mqtt_received_dropped_total 1.0" in text
