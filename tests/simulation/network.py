"""The simulation's network: UDP over :mod:`aiofins.memnet` under the real
:class:`~aiofins.transport.UdpTransport`, FINS/TCP over a stream model of its own.

Datagrams: every session's socket is a real ``UdpTransport`` on the shared in-memory
network (``network=``), so the transport's own code runs; each unit listens on its
``10.0.0.K:9600`` socket there (:class:`UnitPort`), and :meth:`Network.fate` (the network's
fault hook) applies the schedule's link faults: loss, duplication of replies (up to 0.3 s
late), delay (and so reordering). A step of the simulation is one frame put on the wire.

FINS/TCP: :class:`SimStream` keeps the FINS/TCP transport's contract (the handshake assigns
our node, each connection a fresh SID space, in order, a reset ends it) over
:class:`StreamConnection`, a model with the same faults as the units' (resets, refused
handshakes); the real ``TcpTransport`` over memnet's streams would need the units behind the
simulator's FINS/TCP server, which keeps no history: a next step.

Commands are never duplicated by the network: a duplicated command would execute twice and
no client could keep a write at most once; duplicated *replies* are.
"""

from __future__ import annotations

import asyncio
import random
import struct
import zlib
from collections.abc import Callable, Sequence

from aiofins.memnet import DatagramSocket, MemoryNetwork, Packet
from aiofins.protocol.errors import ConnectionLost
from aiofins.transport.base import FrameSink, TaskSpawner, Transport

from .plant import FINS_PORT, Address, Unit

#: Every frame takes at least this long, plus up to ``JITTER`` (seconds).
BASE_DELAY = 0.0005
JITTER = 0.002
#: A duplicated reply comes up to this much later than the first.
DUPLICATE_LAG = 0.3


class Network:
    """Delivers frames between sockets and units with the link faults of the schedule."""

    def __init__(
        self, loop: asyncio.AbstractEventLoop, rng: random.Random, on_step: Callable[[], None]
    ) -> None:
        self.loop = loop
        self.rng = rng
        self.on_step = on_step
        self.units: dict[Address, Unit] = {}
        self.ports: dict[Address, UnitPort] = {}
        self.streams: set[StreamConnection] = set()
        self.digest = 0
        #: Counters that must add up: sent = delivered + lost + nowhere + in flight.
        self.sent = 0
        #: FINS/TCP frames: sent = delivered + flushed + in flight.
        self.streams_sent = 0
        self.delivered = 0
        self.lost = 0
        self.nowhere = 0
        self.flushed = 0
        self.in_flight = 0
        #: Bumped to drop every frame in flight (the schedule's faults end).
        self.epoch = 0

    def add_unit(self, unit: Unit) -> None:
        self.units[unit.address] = unit

    def attach(self, memnet: MemoryNetwork) -> None:
        """Bind every unit's FINS port on ``memnet``."""
        for address, unit in self.units.items():
            self.ports[address] = UnitPort(memnet.datagram_socket(*address), unit, self)

    # -- datagrams (on memnet) ---------------------------------------------------------

    def fate(self, packet: Packet) -> Sequence[float]:
        """memnet's fault hook: the delays of a datagram's copies (none: lost)."""
        self.digest = zlib.crc32(
            struct.pack("<dq", self.loop.time(), packet.number) + packet.data, self.digest
        )
        if packet.kind != "datagram":
            return [0.0]
        to_unit = self.units.get(packet.dest)
        unit = to_unit or self.units.get(packet.source)
        self.sent += 1
        self.on_step()
        faults = unit.faults if unit is not None else {}
        rng = self.rng
        if faults and "loss" in faults and rng.random() < faults["loss"]:
            self.lost += 1
            return []
        delay = self._delay(faults)
        if to_unit is None and faults and "dup" in faults and rng.random() < faults["dup"]:
            return [delay, delay + rng.random() * DUPLICATE_LAG]
        return [delay]

    def reply(self, unit: Unit, to: Address | object, frame: bytes, late: float = 0.0) -> None:
        """A reply from ``unit`` to a socket address or a stream connection."""
        if isinstance(to, StreamConnection):
            to.to_client(frame, late)
            return
        assert isinstance(to, tuple)
        port = self.ports[unit.address]
        if late:
            self.loop.call_later(late, port.send, frame, to, self.epoch)
        else:
            port.send(frame, to, self.epoch)

    def _delay(self, faults: dict[str, float]) -> float:
        d = BASE_DELAY + self.rng.random() * JITTER
        if faults and "delay" in faults:
            d += self.rng.random() * faults["delay"]
        return d

    def flush(self) -> None:
        """Drop every reply not yet sent late, and every stream frame in flight."""
        self.epoch += 1


class UnitPort:
    """A unit's UDP port on memnet: each datagram to the unit, its replies back."""

    def __init__(self, sock: DatagramSocket, unit: Unit, network: Network) -> None:
        self.sock = sock
        self.unit = unit
        self.network = network
        sock.on_readable = self._readable

    def _readable(self) -> None:
        sock, unit = self.sock, self.unit
        while True:
            try:
                frame, source = sock.recvfrom(4096)
            except (BlockingIOError, OSError):
                return
            unit.receive(frame, source)

    def send(self, frame: bytes, to: Address, epoch: int) -> None:
        if epoch == self.network.epoch and not self.sock.closed:
            self.sock.sendto(frame, to)


class StreamConnection:
    """One FINS/TCP connection between a :class:`SimStream` and a unit: in order, no loss;
    a reset ends it for both sides."""

    def __init__(self, network: Network, unit: Unit, client: SimStream) -> None:
        self.network = network
        self.unit = unit
        self.client: SimStream | None = client
        self.last_at = 0.0
        network.streams.add(self)

    def _at(self, extra: float) -> float:
        net = self.network
        at = max(self.last_at, net.loop.time() + net._delay(self.unit.faults) + extra)
        self.last_at = at
        return at

    def to_unit(self, frame: bytes) -> None:
        net = self.network
        net.streams_sent += 1
        net.in_flight += 1
        net.loop.call_at(self._at(0.0), self._arrive, True, frame)

    def to_client(self, frame: bytes, late: float) -> None:
        net = self.network
        net.streams_sent += 1
        net.in_flight += 1
        net.loop.call_at(self._at(late), self._arrive, False, frame)

    def _arrive(self, to_unit: bool, frame: bytes) -> None:
        net = self.network
        net.in_flight -= 1
        if self.client is None:
            net.flushed += 1
            return
        net.delivered += 1
        if to_unit:
            self.unit.receive(frame, self)
        else:
            self.client.stream_frame(frame)
        net.on_step()

    def reset(self) -> None:
        """The connection ends (a TCP reset, a restart of the unit)."""
        client, self.client = self.client, None
        self.network.streams.discard(self)
        if client is not None:
            client.reset()


class SimStream(Transport):
    """A FINS/TCP connection on :class:`Network` (the FINS/TCP transport's contract): the
    handshake assigns our node, every connection starts a fresh SID space."""

    reconnectable = True
    fresh_sid_space = True
    reliable = True
    default_sid_spaces = 2

    def __init__(self, network: Network, unit: Unit) -> None:
        self.network = network
        self.unit = unit
        self.conn: StreamConnection | None = None
        self._sink: FrameSink | None = None

    @property
    def is_open(self) -> bool:
        return self._sink is not None

    @property
    def description(self) -> str:
        return f"tcp://{self.unit.ip}:{FINS_PORT}"

    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        if self._sink is not None:
            return
        await asyncio.sleep(0.001)  # the handshake's round trip
        if "silence" in self.unit.faults or "bad_handshake" in self.unit.faults:
            raise ConnectionLost(f"{self.description}: FINS/TCP handshake refused")
        self.local_node = self.unit.assign_tcp_node()
        self.remote_node = self.unit.number
        self.conn = StreamConnection(self.network, self.unit, self)
        self._sink = sink
        self.fast_send = self._send

    def _send(self, frame: bytes) -> None:
        if self._sink is None or self.conn is None:
            raise ConnectionLost(f"{self.description} is closed")
        self.conn.to_unit(frame)

    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        self._send(frame)

    def stream_frame(self, frame: bytes) -> None:
        if self._sink is not None:
            self._sink.frame_received(frame)

    def reset(self) -> None:
        sink = self._sink
        self._close()
        if sink is not None:
            sink.connection_lost(ConnectionLost(f"{self.description}: connection reset"))

    def another(self) -> SimStream:
        return SimStream(self.network, self.unit)

    def _close(self) -> None:
        conn, self.conn = self.conn, None
        self._sink = None
        self.fast_send = None
        if conn is not None:
            conn.client = None
            self.network.streams.discard(conn)

    async def aclose(self) -> None:
        self._close()
