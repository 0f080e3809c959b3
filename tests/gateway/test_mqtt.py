"""The broker link's QoS 0 path against a hand-built MQTT peer that can stop reading.

QoS 0 messages are written to the socket from :meth:`MqttLink.put` itself; these tests fill
the socket (the peer stops reading, its receive buffer small) so that a write is cut short,
and check that the rest still goes out in order, or, when the connection breaks, that every
message not yet written is back in its outbox, in order.
"""

from __future__ import annotations

import ast
import json
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path

import anyio
import anyio.abc
import pytest
from anyio.abc import SocketAttribute
from anyio.streams.buffered import BufferedByteReceiveStream

from aiofins.gateway.config import MqttConfig
from aiofins.gateway.mqtt import LinkState, MqttLink, Outbox

from .conftest import HANG, Broker, eventually, subscribe

pytestmark = pytest.mark.anyio

SRC = Path(__file__).resolve().parents[2] / "src" / "aiofins"

#: Twelve messages of 512 KB: more than our socket's send buffer (at most 4 MB) and the
#: peer's 4 KB receive buffer hold, so a write is cut short while the peer does not read.
BIG = [bytes([i]) * 512_000 for i in range(12)]


@dataclass
class Peer:
    """A minimal MQTT 3.1.1 broker for one client: CONNACK, SUBACK, PUBACK, PINGRESP; records the
    PUBLISH packets of each connection; reads only while :attr:`reading` is set."""

    port: int
    reading: anyio.Event = field(default_factory=anyio.Event)
    #: (topic, payload) of the PUBLISH packets, one list per connection.
    connections: list[list[tuple[str, bytes]]] = field(default_factory=list)
    changed: anyio.Event = field(default_factory=anyio.Event)
    #: Set to make the peer abort (RST) the current connection.
    abort: anyio.Event = field(default_factory=anyio.Event)

    async def wait_for(self, count: int, connection: int) -> None:
        with anyio.fail_after(HANG):
            while len(self.connections) <= connection or (
                len(self.connections[connection]) < count
            ):
                await self.changed.wait()

    def _note(self) -> None:
        self.changed.set()
        self.changed = anyio.Event()

    async def serve(self, stream: anyio.abc.SocketStream) -> None:
        received: list[tuple[str, bytes]] = []
        self.connections.append(received)
        self._note()
        reader = BufferedByteReceiveStream(stream)
        async with stream, anyio.create_task_group() as tg:

            async def watch_abort() -> None:
                await self.abort.wait()
                sock = stream.extra(SocketAttribute.raw_socket)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\0\0\0\0\0\0\0")
                tg.cancel_scope.cancel()

            tg.start_soon(watch_abort)
            try:
                while True:
                    first = (await reader.receive_exactly(1))[0]
                    length, shift = 0, 0
                    while True:
                        byte = (await reader.receive_exactly(1))[0]
                        length |= (byte & 0x7F) << shift
                        shift += 7
                        if not byte & 0x80:
                            break
                    body = await reader.receive_exactly(length) if length else b""
                    kind = first >> 4
                    if kind == 1:  # CONNECT
                        await stream.send(b"\x20\x02\x00\x00")
                    elif kind == 3:  # PUBLISH
                        size = int.from_bytes(body[:2], "big")
                        topic = body[2 : 2 + size].decode()
                        rest = body[2 + size :]
                        if first & 0x06:  # QoS 1: a packet id, then PUBACK
                            await stream.send(b"\x40\x02" + rest[:2])
                            rest = rest[2:]
                        received.append((topic, rest))
                        self._note()
                        if topic != "s":  # after the link's "online": wait to be let read
                            await self.reading.wait()
                    elif kind == 8:  # SUBSCRIBE (one topic): SUBACK granting QoS 1
                        await stream.send(b"\x90\x03" + body[:2] + b"\x01")
                    elif kind == 12:  # PINGREQ
                        await stream.send(b"\xd0\x00")
                    elif kind == 14:  # DISCONNECT
                        break
            except (anyio.EndOfStream, anyio.BrokenResourceError):
                pass
            tg.cancel_scope.cancel()


@asynccontextmanager
async def mqtt_peer() -> AsyncIterator[Peer]:
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    raw = listener.extra(SocketAttribute.raw_socket)
    raw.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # accepted sockets inherit it
    peer = Peer(listener.extra(SocketAttribute.local_port))
    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(listener.serve, peer.serve)
        yield peer
        tg.cancel_scope.cancel()


def link_to(port: int) -> MqttLink:
    # The hand-built peer speaks MQTT 3.1.1 (the QoS 0 path is the same in 5).
    config = MqttConfig(
        port=port, timeout=2.0, backoff_min=0.05, backoff_max=0.05, protocol="3.1.1"
    )
    return MqttLink(config, client_id="t", status_topic="s")


@asynccontextmanager
async def big_qos0_put(peer: Peer) -> AsyncIterator[tuple[MqttLink, Outbox]]:
    """A link to ``peer``, connected, that has been given every message of BIG at QoS 0 in
    one event-loop step (the socket fills while the peer does not read)."""
    link = link_to(peer.port)
    box = link.outbox("big", qos=0, limit=len(BIG))
    async with anyio.create_task_group() as tg:
        tg.start_soon(link.run)
        with anyio.fail_after(HANG):
            await link.connected.wait()
        for payload in BIG:
            link.put(box, payload)
        yield link, box  # the test closes the link: its run() ends


async def test_a_qos0_write_cut_short_is_finished_in_order(anyio_backend: object) -> None:
    async with mqtt_peer() as peer, big_qos0_put(peer) as (link, box):
        assert not box.messages  # all handed to the connection
        await peer.wait_for(1, 0)  # "online"
        peer.reading.set()
        await peer.wait_for(1 + len(BIG), 0)
        assert peer.connections[0][1:] == [("big", p) for p in BIG]
        assert box.published == len(BIG) and box.dropped == 0
        link.close()


async def test_qos0_messages_not_written_when_the_link_breaks_go_back_to_their_outbox(
    anyio_backend: object,
) -> None:
    async with mqtt_peer() as peer, big_qos0_put(peer) as (link, box):
        peer.abort.set()  # RST while most messages wait to be written
        await eventually(lambda: link.state is not LinkState.CONNECTED)
        # Every message was written (published) or is back in the outbox, in order.
        written = box.published
        assert 0 < len(box.messages) == len(BIG) - written
        assert [p for p, _ in box.messages] == BIG[written:]
        # The next connection sends them.
        peer.abort = anyio.Event()
        peer.reading.set()
        await peer.wait_for(1 + len(BIG) - written, 1)
        assert peer.connections[1][1:] == [("big", p) for p in BIG[written:]]
        assert box.published == len(BIG) and not box.messages
        link.close()


async def test_a_qos0_backlog_goes_out_after_the_connect_in_order(broker: Broker) -> None:
    """Put while no broker is connected: the newest ``limit`` of each outbox are sent, in
    order, the outboxes taking turns."""
    link = link_to(broker.port)
    boxes = [link.outbox(f"t/{i}", qos=0, limit=10) for i in range(3)]
    for n in range(15):
        for box in boxes:
            link.put(box, b"%d" % n)
    assert [b.dropped for b in boxes] == [5, 5, 5]
    async with subscribe(broker.port, "t/#") as sub, anyio.create_task_group() as tg:
        tg.start_soon(link.run)
        await sub.wait_for(lambda: len(sub.messages) == 30)
        for i in range(3):
            assert [m.payload for m in sub.messages if m.topic == f"t/{i}"] == [
                b"%d" % n for n in range(5, 15)
            ]
        assert [b.published for b in boxes] == [10, 10, 10]
        assert [m.topic for m in sub.messages[:3]] == ["t/0", "t/1", "t/2"]  # in turns
        link.close()


async def test_a_qos0_message_is_written_in_put_itself(broker: Broker) -> None:
    """The QoS 0 fast path: a message put into an empty outbox is on the wire when ``put()``
    returns (paho's ``publish()`` with the connection writing at once), no task involved."""
    link = MqttLink(MqttConfig(port=broker.port, timeout=2.0), client_id="f", status_topic="s")
    async with subscribe(broker.port, "fast") as sub, anyio.create_task_group() as tg:
        tg.start_soon(link.run)
        with anyio.fail_after(HANG):
            await link.connected.wait()
        box = link.outbox("fast", qos=0)
        link.put(box, b"x")
        assert box.published == 1 and not box.messages  # handed over and written in put()
        (_, _, info) = link._handed[-1]
        assert info.is_published()  # written to the socket, not queued in paho
        await sub.wait_for(lambda: [m.payload for m in sub.messages] == [b"x"])
        link.close()


def test_the_gateway_uses_no_private_name_of_another_library() -> None:
    """The MQTT layer is built on public APIs only (paho-mqtt's documented API for external
    event loops), so an upgrade cannot break it silently: no ``x._name`` on anything but
    ``self``/``cls``, no ``getattr(x, "_name")``, no private module or name imported."""
    found = []
    for path in sorted((SRC / "gateway").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            where = f"{path.name}:{getattr(node, 'lineno', 0)}"
            if (
                isinstance(node, ast.Attribute)
                and _private(node.attr)
                and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))
            ) or (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id in ("getattr", "setattr", "hasattr")
                and len(node.args) > 1
                and isinstance(node.args[1], ast.Constant)
                and _private(str(node.args[1].value))
            ):
                found.append(f"{where}: {ast.unparse(node)}")
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [a.name for a in node.names]
                if any(_private(part) for part in (node.module or "").split(".")) or any(
                    _private(n) for n in names
                ):
                    found.append(f"{where}: from {node.module} import {', '.join(names)}")
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if any(_private(part) for part in alias.name.split(".")):
                        found.append(f"{where}: import {alias.name}")
    assert found == []


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


async def test_a_clean_stop_is_not_taken_for_a_takeover_by_the_next_start(broker: Broker) -> None:
    """A gateway that stops publishes ``offline`` with ``"stopped": true``, retained; the next
    process finds it on its status topic: a restart, not a second gateway (its last will,
    from a crash, still counts once)."""
    link = MqttLink(MqttConfig(port=broker.port, timeout=2.0), client_id="g", status_topic="st")
    async with anyio.create_task_group() as tg:
        tg.start_soon(link.run)
        with anyio.fail_after(HANG):
            await link.connected.wait()
        link.close()
    async with subscribe(broker.port, "st") as sub:
        await sub.wait_for(lambda: sub.messages)
        (status,) = sub.on("st")
    assert status == {"state": "offline", "instance": link.instance, "stopped": True}
    successor = MqttLink(MqttConfig(port=broker.port), client_id="g", status_topic="st")
    successor._status_seen(json.dumps(status).encode())
    assert successor.takeovers == 0
    will = {"state": "offline", "instance": link.instance}
    successor._status_seen(json.dumps(will).encode())
    assert successor.takeovers == 1
