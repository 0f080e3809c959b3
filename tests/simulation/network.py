"""An in-memory network on the virtual clock, and the transports the sessions use on it.

This is the harness's thin adapter until the shared in-memory datagram/stream network
(under the real UDP and FINS/TCP transports) lands: :class:`SimDatagram` and
:class:`SimStream` implement the transport contract (:class:`aiofins.transport.base.Transport`)
the way the UDP and FINS/TCP transports do (own source node per socket, SID spaces, a
reliable stream with a fresh SID space per connection), with every frame going through
:class:`Network`, which applies the schedule's link faults: loss, duplication of replies,
delay (and so reordering). A step of the simulation is one frame delivered here.

Commands are never duplicated by the network: a duplicated command would execute twice and
no client could keep a write at most once; duplicated *replies* (up to 0.3 s late) are.
"""

from __future__ import annotations

import asyncio
import random
from collections.abc import Callable

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
        self.sockets: dict[Address, SimDatagram] = {}
        self.units: dict[Address, Unit] = {}
        self.streams: set[StreamConnection] = set()
        self.next_port = 50000
        #: Counters that must add up: sent = delivered + lost + nowhere + in flight.
        self.sent = 0
        self.delivered = 0
        self.lost = 0
        self.nowhere = 0
        self.flushed = 0
        self.in_flight = 0
        #: Bumped to drop every frame in flight (the schedule's faults end).
        self.epoch = 0

    def add_unit(self, unit: Unit) -> None:
        self.units[unit.address] = unit

    # -- datagrams ---------------------------------------------------------------------

    def bind(self, sock: SimDatagram) -> Address:
        """A free port on the socket's host: the FINS port if free (the table's port),
        else the next ephemeral one."""
        if (sock.host, FINS_PORT) not in self.sockets:
            addr = (sock.host, FINS_PORT)
        else:
            self.next_port += 1
            addr = (sock.host, self.next_port)
        self.sockets[addr] = sock
        return addr

    def unbind(self, addr: Address) -> None:
        self.sockets.pop(addr, None)

    def _faults(self, unit: Unit | None) -> dict[str, float]:
        return unit.faults if unit is not None else {}

    def send(self, src: Address, dst: Address, frame: bytes) -> None:
        """A command datagram from a socket to a unit."""
        unit = self.units.get(dst)
        faults = self._faults(unit)
        self.sent += 1
        if faults and "loss" in faults and self.rng.random() < faults["loss"]:
            self.lost += 1
            return
        self._schedule(self._delay(faults), src, dst, frame)

    def reply(self, unit: Unit, to: Address | object, frame: bytes, late: float = 0.0) -> None:
        """A reply from ``unit`` to a socket address or a stream connection."""
        if isinstance(to, StreamConnection):
            to.to_client(frame, late)
            return
        assert isinstance(to, tuple)
        faults = unit.faults
        self.sent += 1
        rng = self.rng
        if faults and "loss" in faults and rng.random() < faults["loss"]:
            self.lost += 1
            return
        delay = self._delay(faults) + late
        self._schedule(delay, unit.address, to, frame)
        if faults and "dup" in faults and rng.random() < faults["dup"]:
            self.sent += 1
            self._schedule(delay + rng.random() * DUPLICATE_LAG, unit.address, to, frame)

    def _delay(self, faults: dict[str, float]) -> float:
        d = BASE_DELAY + self.rng.random() * JITTER
        if faults and "delay" in faults:
            d += self.rng.random() * faults["delay"]
        return d

    def _schedule(self, delay: float, src: Address, dst: Address, frame: bytes) -> None:
        self.in_flight += 1
        self.loop.call_at(self.loop.time() + delay, self._arrive, self.epoch, src, dst, frame)

    def _arrive(self, epoch: int, src: Address, dst: Address, frame: bytes) -> None:
        self.in_flight -= 1
        if epoch != self.epoch:
            self.flushed += 1
            return
        self.delivered += 1
        unit = self.units.get(dst)
        if unit is not None:
            unit.receive(frame, src)
        else:
            sock = self.sockets.get(dst)
            if sock is None:
                self.nowhere += 1
            else:
                sock.datagram(frame)
        self.on_step()

    def flush(self) -> None:
        """Drop every frame in flight (late replies included): what arrives from now on was
        sent from now on."""
        self.epoch += 1


class SimDatagram(Transport):
    """A UDP socket on :class:`Network` (the UDP transport's contract)."""

    reconnectable = True
    own_source_node = True
    default_sid_spaces = 4

    def __init__(self, network: Network, host: str, peer: Address) -> None:
        self.network = network
        self.host = host
        self.peer = peer
        self.addr: Address | None = None
        self._sink: FrameSink | None = None

    @property
    def is_open(self) -> bool:
        return self._sink is not None

    @property
    def description(self) -> str:
        return f"udp://{self.peer[0]}:{self.peer[1]}"

    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        if self._sink is not None:
            return
        self.addr = self.network.bind(self)
        self._sink = sink
        self.fast_send = self._send

    def _send(self, frame: bytes) -> None:
        if self._sink is None or self.addr is None:
            raise ConnectionLost(f"{self.description} is closed")
        self.network.send(self.addr, self.peer, frame)

    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        self._send(frame)

    def datagram(self, frame: bytes) -> None:
        sink = self._sink
        if sink is not None:
            sink.frame_received(frame)

    def another(self) -> SimDatagram:
        return SimDatagram(self.network, self.host, self.peer)

    async def aclose(self) -> None:
        if self.addr is not None:
            self.network.unbind(self.addr)
        self.addr = None
        self._sink = None
        self.fast_send = None


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
        net.sent += 1
        net.in_flight += 1
        net.loop.call_at(self._at(0.0), self._arrive, True, frame)

    def to_client(self, frame: bytes, late: float) -> None:
        net = self.network
        net.sent += 1
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
