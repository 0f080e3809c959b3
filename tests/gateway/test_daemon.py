"""The gateway against a real Mosquitto and virtual PLCs on loopback UDP."""

from __future__ import annotations

import logging
from contextlib import AsyncExitStack
from pathlib import Path

import anyio
import anyio.abc
import httpx
import pytest

from aiofins.gateway import Gateway, LinkState, PlcState, Shard
from aiofins.gateway.config import GatewayConfig, parse_config
from aiofins.simulator import VirtualPLC, run_simulator

from .conftest import (
    HANG,
    Broker,
    Subscriber,
    eventually,
    free_port,
    need_mosquitto,
    publisher,
    simulators,
    subscribe,
)

pytestmark = pytest.mark.anyio


def config(broker: Broker, body: str, *, http: bool = False, timeout: float = 0.5) -> GatewayConfig:
    head = f"""
[gateway]
name = "gw"
[mqtt]
port = {broker.port}
backoff_min = 0.05
backoff_max = 0.2
timeout = 2
[http]
enabled = {"true" if http else "false"}
port = 0
[connect]
timeout = {timeout}
retries = 0
"""
    return parse_config(head + body, "test.toml")


async def test_values_arrive_on_their_topics_with_their_quality(broker: Broker) -> None:
    plc = VirtualPLC()
    plc.write_value("D100", 71.25, "float32")
    plc.write("D110", [0x00AB])  # no BCD value: this tag's quality is ERROR
    plc.write("CIO 0", [0b10])
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        cfg = config(
            broker,
            f"""
[[groups]]
name = "fast"
interval = 0.05
tags = {{ temp = "D100:float32", run = "CIO 0.01", code = "D110:bcd16" }}
[[plcs]]
name = "press1"
url = "udp://127.0.0.1:{sim.udp_port}"
[[plcs]]
name = "gone"
url = "udp://127.0.0.1:{free_port()}"
""",
            http=True,
        )
        async with (
            subscribe(broker.port, "fins/#") as sub,
            Gateway(cfg) as gateway,
        ):
            await sub.wait_for(lambda: len(sub.on("fins/press1/fast")) >= 2)
            first = sub.on("fins/press1/fast")[0]
            assert first["plc"] == "press1" and first["group"] == "fast" and first["scan"] == 1
            assert first["error"] is None
            temp, run, code = (first["values"][n] for n in ("temp", "run", "code"))
            assert temp["value"] == 71.25 and temp["quality"] == "GOOD"
            assert temp["timestamp"] == first["timestamp"]
            assert run == {"value": True, "quality": "GOOD", "timestamp": first["timestamp"]}
            assert code["quality"] == "ERROR" and code["value"] is None
            assert "code" in code["error"] and "BCD" in code["error"]
            plc.write("D110", [0x0042])  # now good; then the PLC keeps the last good value
            await sub.wait_for(
                lambda: sub.on("fins/press1/fast")[-1]["values"]["code"]["quality"] == "GOOD"
            )
            assert sub.on("fins/press1/fast")[-1]["values"]["code"]["value"] == 42
            plc.write("D110", [0x00AB])
            await sub.wait_for(
                lambda: sub.on("fins/press1/fast")[-1]["values"]["code"]["quality"] == "STALE"
            )
            stale = sub.on("fins/press1/fast")[-1]["values"]["code"]
            assert (
                stale["value"] == 42
                and stale["timestamp"] < sub.on("fins/press1/fast")[-1]["timestamp"]
            )
            # The PLC nobody answers for: ERROR readings, offline status, all retained statuses.
            await sub.wait_for(lambda: sub.on("fins/gone/fast") and sub.on("fins/gone/status"))
            gone = sub.on("fins/gone/fast")[0]
            assert gone["error"].startswith("FinsTimeout")
            assert {r["quality"] for r in gone["values"].values()} == {"ERROR"}
            assert sub.on("fins/gone/status") == [
                {"state": "offline", "plc": "gone", "gateway": "gw", "error": gone["error"]}
            ]
            assert sub.on("fins/press1/status") == [
                {"state": "online", "plc": "press1", "gateway": "gw"}
            ]
            instance = gateway.link.instance  # host:pid:random, to tell two instances apart
            assert sub.on("fins/_gateway/gw") == [{"state": "online", "instance": instance}]
            assert gateway.plc_status["gone"].state is PlcState.OFFLINE
            await gateway.wait_scanned()  # both first scans ended (the gone one failed)
            assert [r.scanned for r in gateway.routes.values()] == [True, True]
            # Health and metrics over HTTP.
            async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{gateway.http_port}") as http:
                health = await http.get("/healthz")
                ready = await http.get("/readyz")
                metrics = await http.get("/metrics")
                missing = await http.get("/nope")
            assert health.status_code == 200 and ready.status_code == 200
            assert health.json()["mqtt"] == "connected"
            assert health.json()["plcs"] == {"unknown": 0, "online": 1, "offline": 1}
            assert missing.status_code == 404
            text = metrics.text
            assert 'aiofins_gateway_scans_total{group="fast",plc="press1"}' in text
            assert 'aiofins_gateway_plc_online{plc="gone"} 0.0' in text
            assert "aiofins_gateway_mqtt_connected 1.0" in text
            assert "aiofins_gateway_publish_latency_seconds_count" in text
            assert "aiofins_gateway_loop_lag_seconds_count" in text
            assert "aiofins_request_duration_seconds" in text  # the library's own metrics
        # Stopped: the gateway says so (retained), and it is the last word on its topic.
        async with subscribe(broker.port, "fins/_gateway/#") as late:
            await late.wait_for(lambda: late.messages)
            assert late.messages[0].retain
            assert late.on("fins/_gateway/gw") == [
                {"state": "offline", "instance": instance, "stopped": True}
            ]


async def test_changes_only_publishes_the_tags_that_changed(broker: Broker) -> None:
    plc = VirtualPLC()
    plc.write("D0", [1, 2])
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        cfg = config(
            broker,
            f"""
[[groups]]
name = "c"
interval = 0.05
changes_only = true
tags = {{ a = "D0", b = "D1" }}
[[plcs]]
name = "p"
url = "udp://127.0.0.1:{sim.udp_port}"
""",
        )
        async with subscribe(broker.port, "fins/p/c") as sub, Gateway(cfg) as gateway:
            await sub.wait_for(lambda: sub.messages)
            first = sub.on("fins/p/c")[0]
            assert first["scan"] == 1 and first["values"].keys() == {"a", "b"}
            route = gateway.routes["p/c"]
            await eventually(lambda: route.scans >= 5)  # scans without changes publish nothing
            assert len(sub.messages) == 1 and route.outbox.published == 1
            counted = route.scans  # (the last one counted may not have read the PLC yet)
            plc.write("D1", [7])
            await sub.wait_for(lambda: len(sub.messages) == 2)
            second = sub.on("fins/p/c")[1]
            assert second["scan"] >= counted >= 5
            assert second["values"] == {
                "b": {"value": 7, "quality": "GOOD", "timestamp": second["timestamp"]}
            }


async def test_a_plc_killed_and_restarted_goes_offline_and_online_once_each(
    broker: Broker,
) -> None:
    plc = VirtualPLC()
    port = free_port()
    cfg = config(
        broker,
        f"""
[[groups]]
name = "g"
interval = 0.05
tags = {{ x = "D0" }}
[[groups]]
name = "h"
interval = 0.07
tags = {{ y = "D1" }}
[[plcs]]
name = "p1"
url = "udp://127.0.0.1:{port}"
""",
    )

    async def serve(stop: anyio.Event, *, task_status: anyio.abc.TaskStatus[None]) -> None:
        async with run_simulator(plc, udp=("127.0.0.1", port)):
            task_status.started()
            await stop.wait()

    async with anyio.create_task_group() as tg:
        killed = anyio.Event()
        await tg.start(serve, killed)  # the PLC answers before the gateway starts
        async with subscribe(broker.port, "fins/p1/#") as sub, Gateway(cfg) as gateway:

            def scans() -> int:
                return len(sub.on("fins/p1/g"))

            await sub.wait_for(lambda: scans() >= 3 and sub.on("fins/p1/status"))
            killed.set()
            await sub.wait_for(lambda: len(sub.on("fins/p1/status")) >= 2)
            down_at = scans()
            await sub.wait_for(lambda: scans() >= down_at + 5)  # failed scans of each group
            await tg.start(serve, anyio.Event())
            await sub.wait_for(lambda: len(sub.on("fins/p1/status")) >= 3)
            up_at = scans()
            await sub.wait_for(lambda: scans() >= up_at + 5)
        tg.cancel_scope.cancel()  # the restarted PLC
    states = [m["state"] for m in sub.on("fins/p1/status")]
    assert states == ["online", "offline", "online"]
    assert gateway.plc_status["p1"].transitions == 3
    assert gateway.plc_status["p1"].state is PlcState.ONLINE


async def test_broker_killed_and_restarted_loses_only_what_the_buffer_bound_drops(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    need_mosquitto()
    caplog.set_level(logging.INFO, logger="aiofins.gateway")
    broker = Broker(tmp_path, persistence=True)
    await anyio.to_thread.run_sync(broker.start)
    try:
        async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
            cfg = config(
                broker,
                f"""
[[groups]]
name = "g"
interval = 0.02
qos = 1
buffer = 5
tags = {{ x = "D0" }}
[[plcs]]
name = "p1"
url = "udp://127.0.0.1:{sim.udp_port}"
""",
            )
            received = Subscriber()
            async with Gateway(cfg) as gateway:
                route = gateway.routes["p1/g"]
                # A persistent session: the broker keeps its messages across the restart.
                async with subscribe(
                    broker.port, "fins/p1/g", identifier="h8-sub", clean=False, into=received
                ):
                    await received.wait_for(lambda: len(received.messages) >= 3)
                    # Scans published before the subscription existed are no one's to get:
                    # count from the first one it got.
                    first = min(m.json()["scan"] for m in received.messages)
                    await anyio.to_thread.run_sync(broker.stop)
                    await eventually(lambda: gateway.link.state is not LinkState.CONNECTED)
                    down = route.scans
                    # The outbox overflows while the broker is away.
                    await eventually(lambda: route.scans >= down + 20)
                    assert route.outbox.dropped >= 10
                    assert len(route.outbox.messages) == 5
                await anyio.to_thread.run_sync(broker.start)
                with anyio.fail_after(HANG):
                    await gateway.link.connected.wait()
                async with subscribe(
                    broker.port, "fins/p1/g", identifier="h8-sub", clean=False, into=received
                ):
                    last = route.scans

                    def missing() -> set[int]:
                        scans = {m.json()["scan"] for m in received.messages}
                        return set(range(first, max(scans) + 1)) - scans

                    await received.wait_for(
                        lambda: max(m.json()["scan"] for m in received.messages) >= last
                    )
                    # Every scan arrives or is one the outbox dropped, counted (QoS 1 may
                    # deliver the kept ones a little out of order: wait for them).
                    await received.wait_for(lambda: len(missing()) == route.outbox.dropped)
                    lost, dropped = missing(), route.outbox.dropped
        assert lost, "the outage should have cost some scans"
        assert len(lost) == dropped, (
            sorted(lost),
            dropped,
            sorted({m.json()["scan"] for m in received.messages}),
        )
        assert gateway.link.connects == 2 and gateway.link.connect_failures >= 1
        # The PLC's state went to the new broker again, but it did not change: one line.
        online = [r for r in caplog.records if r.getMessage() == "PLC p1 is online"]
        assert len(online) == 1
    finally:
        broker.stop()


async def test_the_pool_keeps_a_session_for_every_plc_of_the_shard() -> None:
    """More PLCs than the pool's default bound (256 sessions): each keeps its session (the
    gateway once evicted and reopened a session on nearly every scan past 256 PLCs)."""
    plcs = "".join(
        f'[[plcs]]\nname = "p{i}"\nurl = "udp://127.0.0.1:{10000 + i}"\n' for i in range(600)
    )
    cfg = parse_config(
        '[http]\nenabled = false\n[[groups]]\nname = "g"\ntags = { x = "D0" }\n' + plcs, "t.toml"
    )
    assert Gateway(cfg).pool.max_sessions >= 600
    shard = Gateway(cfg, shard=Shard(1, 2))
    assert len(shard.plcs) < shard.pool.max_sessions < 600


async def test_two_shards_publish_every_plc_exactly_once_between_them(broker: Broker) -> None:
    count = 200
    async with AsyncExitStack() as stack:
        sims = await stack.enter_async_context(simulators(count))
        plcs = "".join(
            f'[[plcs]]\nname = "plc{i:03}"\nurl = "udp://127.0.0.1:{sim.udp_port}"\n'
            for i, sim in enumerate(sims)
        )
        group = '[[groups]]\nname = "g"\ninterval = 0.5\ntags = { x = "D0" }\n'
        cfg = config(broker, group + plcs, timeout=2.0)
        sub = await stack.enter_async_context(subscribe(broker.port, "fins/+/status", "fins/+/g"))
        gateways = [
            await stack.enter_async_context(Gateway(cfg, shard=Shard(i, 2))) for i in range(2)
        ]
        names = {f"plc{i:03}" for i in range(count)}

        def published() -> set[str]:
            return {m.topic.split("/")[1] for m in sub.messages if m.topic.endswith("/g")}

        def announced() -> set[str]:
            return {m.topic.split("/")[1] for m in sub.messages if m.topic.endswith("/status")}

        # Statuses (QoS 1, their own outboxes) may arrive after the first scans.
        await sub.wait_for(lambda: published() == names == announced())
        mine = [{p.name for p in gw.plcs} for gw in gateways]
        assert mine[0] | mine[1] == names and not mine[0] & mine[1]
        assert 60 < len(mine[0]) < 140  # rendezvous hashing spreads them
        # Each PLC's status comes from the gateway that owns it (a PLC slow to answer on this
        # busy machine may go offline and back: still from its owner only).
        statuses = [m.json() for m in sub.messages if m.topic.endswith("/status")]
        by_plc: dict[str, set[str]] = {}
        for status in statuses:
            by_plc.setdefault(status["plc"], set()).add(status["gateway"])
        assert set(by_plc) == names
        for gw, owned in zip(gateways, mine, strict=True):
            assert {p for p, g in by_plc.items() if g == {gw.name}} == owned
        first_scans = [(m.topic, m.json()["scan"]) for m in sub.messages if m.topic.endswith("/g")]
        assert len(first_scans) == len(set(first_scans))  # no scan published twice


async def test_writes_only_for_allowlisted_tags_answered_with_the_end_code(
    broker: Broker,
) -> None:
    plc = VirtualPLC()
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        cfg = config(
            broker,
            f"""
[[groups]]
name = "w"
interval = 0.1
tags = {{ sp = "D120:int16", other = "D121", ro = "A0", run = "CIO 0.03", name = "D130:string:4" }}
writable = ["sp", "ro", "run", "name"]
[[groups]]
name = "r"
interval = 0.1
tags = {{ sp2 = "D122" }}
[[plcs]]
name = "p1"
url = "udp://127.0.0.1:{sim.udp_port}"
""",
        )
        base = "fins/p1/w/set"
        async with (
            subscribe(broker.port, f"{base}/+/reply") as sub,
            Gateway(cfg) as gateway,
            publisher(broker.port) as pub,
        ):
            await gateway.link.connected.wait()

            async def ask(tag: str, payload: str, topic: str = base) -> dict[str, object]:
                before = len(sub.on(f"{base}/{tag}/reply"))
                await pub.publish(f"{topic}/{tag}", payload, qos=1)
                await sub.wait_for(lambda: len(sub.on(f"{base}/{tag}/reply")) > before)
                reply: dict[str, object] = sub.on(f"{base}/{tag}/reply")[-1]
                waited = reply.pop("waited")
                assert (waited is None) is (reply["end_code"] is None), reply
                return reply

            await pub.publish("fins/p1/r/set/sp2", "7", qos=1)  # no writable tag: nobody listens
            assert await ask("sp", '{"value": -12, "id": "a1"}') == {
                "tag": "sp",
                "id": "a1",
                "ok": True,
                "end_code": "0000",
                "error": None,
            }
            assert plc.read_value("D120", "int16") == -12
            assert await ask("run", "true") == {
                "tag": "run",
                "id": None,
                "ok": True,
                "end_code": "0000",
                "error": None,
            }
            assert plc.read("CIO 0.03", 1) == [1]
            assert (await ask("name", '"AB"'))["ok"] is True
            assert plc.read_value("D130", "string:4") == "AB"
            refused = await ask("other", "5")
            assert refused["ok"] is False and refused["end_code"] is None
            assert "not writable" in str(refused["error"])
            assert plc.read("D121", 1) == [0]
            plc_answer = await ask("ro", "1")  # the PLC refuses: its end code comes back
            assert plc_answer["ok"] is False and plc_answer["end_code"] == "2101"
            for bad, why in [
                ("abc", "not JSON"),
                ("1.5", "whole number"),
                ("70000", "out of range -32768..32767"),
                ("true", "whole number"),
                ('{"value": 1, "bogus": 2}', "unknown key"),
                ('{"id": 3}', 'needs "value"'),
                ("\xff", "not JSON"),
            ]:
                reply = await ask("sp", bad)
                assert reply["ok"] is False and why in str(reply["error"]), (bad, reply)
            assert (await ask("name", "12"))["ok"] is False
            assert (await ask("run", "2"))["ok"] is False
            assert plc.read_value("D120", "int16") == -12  # nothing written by the bad ones
            assert plc.read("D122", 1) == [0]
            assert gateway.write_counts == {"written": 3, "refused": 1, "failed": 1, "invalid": 9}
            assert sub.on("fins/p1/r/set/sp2/reply") == []
            assert gateway.link.state is LinkState.CONNECTED
            assert gateway.routes["p1/w"].errors == 0
