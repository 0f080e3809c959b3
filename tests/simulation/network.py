"""The simulation's network: :mod:`aiofins.memnet` under the real
:class:`~aiofins.transport.UdpTransport` and :class:`~aiofins.transport.TcpTransport`.

Every client socket and connection is a real transport on the shared in-memory network
(``network=``), so the transports' own code runs (FINS/TCP's handshake and framing
included). Each unit listens on ``10.0.0.K:9600`` there, for datagrams (:class:`UnitPort`)
and for FINS/TCP connections (:class:`TcpPort`, one :class:`TcpClient` per connection: the
node-address handshake, then each FINS frame to the unit and its replies back, in order).
:meth:`Network.fate` (memnet's fault hook) applies the schedule's link faults: loss,
duplication of replies (up to 0.3 s late), delay (and so reordering); over FINS/TCP, delay
and frames split in pieces; resets come from the schedule (``tcp_reset``, ``restart``). A
step of the simulation is one datagram or FINS/TCP message put on the wire.

Where a UDP reply goes is the unit's address conversion
(:class:`~aiofins.simulator.EthernetUnit`, the simulator's and ``aiofins doctor``'s model),
decided when the reply is sent.

Commands are never duplicated by the network: a duplicated command would execute twice and
no client could keep a write at most once; duplicated *replies* are.
"""

from __future__ import annotations

import asyncio
import random
import struct
import zlib
from collections import deque
from collections.abc import Callable, Sequence

import anyio

from aiofins.memnet import DatagramSocket, MemoryNetwork, MemoryStream, Packet, StreamListener
from aiofins.protocol.tcp import (
    TcpCommand,
    TcpDecoder,
    TcpErrorCode,
    encode_message,
    encode_node_response,
)

from .plant import Address, Unit

#: Every frame takes at least this long, plus up to ``JITTER`` (seconds).
BASE_DELAY = 0.0005
JITTER = 0.002
#: A duplicated reply comes up to this much later than the first.
DUPLICATE_LAG = 0.3
#: The share of FINS/TCP messages split in two pieces on the wire (while a fault is on).
SPLIT = 0.2


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
        self.listeners: dict[Address, TcpPort] = {}
        self.memnet: MemoryNetwork | None = None
        self.digest = 0
        #: Datagrams and FINS/TCP messages put on the wire, and those the hook lost.
        self.sent = 0
        self.lost = 0
        #: UDP replies the unit's address conversion had no address for.
        self.unaddressed = 0
        #: Bumped to drop every late reply not yet sent (the schedule's faults end).
        self.epoch = 0
        #: Ground truth of the duplicates: every reply copy the network made, as (when it
        #: arrives, the socket it goes to, its bytes, when its original was sent, the unit
        #: that sent it, the socket its command came from), in the order they were made.
        self.copies: list[tuple[float, Address, bytes, float, Address, object]] = []
        #: Ground truth of the original replies over UDP: each as (when it was sent, when
        #: it arrives, the socket it goes to, the socket its command came from, its bytes).
        self.originals: list[tuple[float, float, Address, object, bytes]] = []
        #: Ground truth of the UDP commands that reached a unit: by (the socket it came
        #: from, the unit, its SID), each as (when it was sent, when it arrived, what it
        #: asked: its bytes from the command code on).
        self.commands: dict[tuple[object, Address, int], list[tuple[float, float, bytes]]] = {}
        #: Of each original reply (same order as :attr:`originals`), the unit that sent it
        #: and its round trip: from the send of the command it answers (the latest under
        #: its SID that had reached the unit) to its arrival (0.0: no command found).
        self.round_trips: list[tuple[Address, float]] = []
        #: Where the command of the UDP reply being sent came from (set by :meth:`_send`).
        self._answering: object = None

    def add_unit(self, unit: Unit) -> None:
        self.units[unit.address] = unit

    async def attach(self, memnet: MemoryNetwork, tg: anyio.abc.TaskGroup) -> None:
        """Bind every unit's FINS port (UDP and TCP) on ``memnet``."""
        self.memnet = memnet
        for address, unit in self.units.items():
            self.ports[address] = UnitPort(memnet.datagram_socket(*address), unit, self)
            port = self.listeners[address] = TcpPort(memnet.listen(*address), unit, self)
            tg.start_soon(port.serve)

    def close(self) -> None:
        for port in self.ports.values():
            port.sock.close()
        for listener in self.listeners.values():
            listener.listener.close()

    def reset(self, unit: Unit) -> None:
        """Reset every FINS/TCP connection of ``unit`` (a TCP reset, a restart)."""
        if self.memnet is None:  # (not running yet: no connection)
            return
        for stream in list(self.memnet.streams):
            if stream.local == unit.address:
                self.memnet.reset(stream)

    # -- the fault hook ------------------------------------------------------------------

    def fate(self, packet: Packet) -> Sequence[float]:
        """memnet's fault hook: the delays of a datagram's copies (none: lost), of a
        FINS/TCP message's pieces, of a connection request."""
        self.digest = zlib.crc32(
            struct.pack("<dq", self.loop.time(), packet.number) + packet.data, self.digest
        )
        to_unit = self.units.get(packet.dest)
        unit = to_unit or self.units.get(packet.source)
        faults = unit.faults if unit is not None else {}
        rng = self.rng
        if packet.kind == "connect":
            return [] if "silence" in faults else [self._delay(faults)]
        self.sent += 1
        self.on_step()
        if packet.kind == "stream":
            delay = self._delay(faults)
            if faults and len(packet.data) > 1 and rng.random() < SPLIT:
                return [delay, delay + rng.random() * JITTER]
            return [delay]
        if faults and "loss" in faults and rng.random() < faults["loss"]:
            self.lost += 1
            return []
        delay = self._delay(faults)
        if to_unit is not None and len(packet.data) > 9:
            now = self.loop.time()
            key = (packet.source, packet.dest, packet.data[9])
            self.commands.setdefault(key, []).append((now, now + delay, packet.data[10:]))
        if to_unit is None and faults and "dup" in faults and rng.random() < faults["dup"]:
            lag = delay + rng.random() * DUPLICATE_LAG
            now = self.loop.time()
            self.copies.append(
                (now + lag, packet.dest, packet.data, now, packet.source, self._answering)
            )
            self._original(packet, delay)
            return [delay, lag]
        if to_unit is None:
            self._original(packet, delay)
        return [delay]

    def _original(self, packet: Packet, delay: float) -> None:
        now = self.loop.time()
        self.originals.append((now, now + delay, packet.dest, self._answering, packet.data))
        asked = (
            self._asked(self._answering, packet.source, packet.data[9], now)
            if len(packet.data) > 9
            else None
        )
        rtt = now + delay - asked if asked is not None else 0.0
        self.round_trips.append((packet.source, rtt))

    def _asked(self, source: object, unit: Address, sid: int, before: float) -> float | None:
        """When the latest command from ``source`` to ``unit`` under ``sid`` that had
        reached the unit by ``before`` was sent (``None``: none)."""
        for sent, arrived, _ in reversed(self.commands.get((source, unit, sid), ())):
            if arrived <= before + 1e-12:
                return sent
        return None

    def copy_answered(self, data: bytes, start: float, end: float, head: bytes = b"") -> str:
        """Ground truth for a wrong answer returned between ``start`` and ``end``: whether a
        copy the network made of a reply holding ``data`` (after the command code and end
        code; ``head``: what the reply's bytes from its command code on begin with, for a
        write's) arrived meanwhile: ``"first"`` if it was the first copy ever to reach its
        socket (the link had shown no duplicate), ``"poll"`` if not but it copied the reply
        to the same question asked under its SID just before the call's (:meth:`_asked_again`),
        ``"copy"`` if neither, ``""`` if none came."""
        for at, dest, frame, sent, unit, asker in self.copies:
            if not start - 1e-9 <= at <= end + 1e-9:
                continue
            if frame[14:] != data or not frame[10:].startswith(head):
                continue
            if not any(a < at and d == dest for a, d, *_ in self.copies):
                return "first"
            return "poll" if self._asked_again(start, at, (asker, unit, frame[9]), sent) else "copy"
        return ""

    def _asked_again(
        self, start: float, at: float, key: tuple[object, Address, int], sent: float
    ) -> bool:
        """Whether a copy arriving ``at`` of a reply sent at ``sent`` (to the command under
        ``key``: its socket, unit and SID) copied the reply to the same question as the
        call that began at ``start`` asked under that SID: the command it answered was sent
        before ``start``, and every command under the SID since, the call's first among
        them, asked the same (its bytes from the command code on). No client tells that
        copy from the call's own reply (docs/session.md, "What stays exposed": a poll)."""
        commands = self.commands.get(key, ())
        answered = [c for c in commands if c[1] <= sent + 1e-12]
        if not answered or answered[-1][0] >= start:
            return False
        since, _, question = answered[-1]
        later = [c for c in commands if since < c[0] <= at]
        return bool(later) and later[0][0] >= start and all(c[2] == question for c in later)

    def original_answered(self, data: bytes, start: float, end: float, head: bytes = b"") -> str:
        """Ground truth for a wrong answer returned between ``start`` and ``end`` that no
        copy explains (:meth:`copy_answered`): whether an original UDP reply holding
        ``data`` (as there) arrived meanwhile, and what it was: ``"misrouted"`` if it went
        to another socket than the one its command came from (a fixed reply port: issue
        #22's defect 2), ``"late"`` if it went back to its command's socket but was sent
        before the call began (the reply to an earlier request, given up on: its SID was
        reused while it was on its way), ``""`` if neither."""
        for i, (sent, at, dest, sender, frame) in enumerate(self.originals):
            if not start - 1e-9 <= at <= end + 1e-9:
                continue
            if frame[14:] != data or not frame[10:].startswith(head):
                continue
            if sender != dest:
                return "misrouted"
            if sent < start:
                return "slow" if self._first_slow(i, start, at) else "late"
        return ""

    def _first_slow(self, i: int, start: float, at: float) -> bool:
        """Whether the late original reply ``originals[i]`` took a round trip longer than
        twice any the link (its unit and socket) had shown when its SID was reused: by
        the send of the command under that SID that began at or after ``start`` (the call
        it answered). No quarantine bounded by the round trips shown could have held its
        SID (docs/session.md, "What stays exposed": the episode's first slow reply)."""
        _, _, dest, _, frame = self.originals[i]
        unit, round_trip = self.round_trips[i]
        sends = [s for s, _, _ in self.commands.get((dest, unit, frame[9]), ()) if start <= s <= at]
        if not sends or not round_trip:
            return False
        reused = sends[0]
        replies = zip(self.originals, self.round_trips, strict=True)
        shown = max(
            (
                rtt
                for (_, a, d, sender, _), (u, rtt) in replies
                if a < reused and d == dest and sender == dest and u == unit
            ),
            default=0.0,
        )
        return round_trip > 2 * shown

    def _delay(self, faults: dict[str, float]) -> float:
        d = BASE_DELAY + self.rng.random() * JITTER
        if faults and "delay" in faults:
            d += self.rng.random() * faults["delay"]
        return d

    # -- replies -------------------------------------------------------------------------

    def reply(self, unit: Unit, to: object, frame: bytes, late: float = 0.0) -> None:
        """A reply from ``unit`` to a UDP command (``to``: where it came from) or over a
        FINS/TCP connection (``to``: the :class:`TcpClient`), ``late`` seconds from now."""
        if late:
            self.loop.call_later(late, self._send, unit, to, frame, self.epoch)
        else:
            self._send(unit, to, frame, self.epoch)

    def _send(self, unit: Unit, to: object, frame: bytes, epoch: int) -> None:
        if epoch != self.epoch:
            return
        if isinstance(to, TcpClient):
            to.send(frame)
            return
        dest = unit.ethernet.destination(frame)  # decided now, as a unit does
        if dest is None:
            self.unaddressed += 1
            return
        port = self.ports[unit.address]
        if not port.sock.closed:
            self._answering = to
            port.sock.sendto(frame, dest)
            self._answering = None

    def flush(self) -> None:
        """Drop every reply not yet sent late."""
        self.epoch += 1


class UnitPort:
    """A unit's UDP port on memnet: each datagram to the unit (its address conversion
    learns the sender), the replies back (see :meth:`Network.reply`)."""

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
            unit.ethernet.received(frame, source)
            unit.receive(frame, source)


class TcpPort:
    """A unit's FINS/TCP port on memnet: accepts connections, serves each."""

    def __init__(self, listener: StreamListener, unit: Unit, network: Network) -> None:
        self.listener = listener
        self.unit = unit
        self.network = network

    async def serve(self) -> None:
        async with anyio.create_task_group() as tg:
            while True:
                try:
                    stream = await self.listener.accept()
                except anyio.ClosedResourceError:
                    return
                tg.start_soon(TcpClient(stream, self.unit).run)


class TcpClient:
    """The unit's end of one FINS/TCP connection: the node-address handshake (refused while
    the schedule says ``bad_handshake``, unanswered while the unit is silent), then FINS
    frames to the unit and its replies back in order."""

    def __init__(self, stream: MemoryStream, unit: Unit) -> None:
        self.stream = stream
        self.unit = unit
        self.outbox: deque[bytes] = deque()
        self.ready = asyncio.Event()
        self.open = False
        self.closed = False

    def send(self, frame: bytes) -> None:
        if self.open and not self.closed:
            self.outbox.append(encode_message(TcpCommand.FRAME, frame))
            self.ready.set()

    async def run(self) -> None:
        async with anyio.create_task_group() as tg:
            tg.start_soon(self._write)
            try:
                await self._read()
            except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
                pass
            finally:
                self.closed = True
                tg.cancel_scope.cancel()
                self.stream.close()

    async def _read(self) -> None:
        decoder = TcpDecoder()
        unit = self.unit
        while True:
            for message in decoder.feed(await self.stream.receive()):
                if message.command == TcpCommand.FRAME and self.open:
                    unit.receive(message.payload, self)
                elif message.command == TcpCommand.NODE_ADDRESS_REQUEST and not self.open:
                    if "silence" in unit.faults:
                        continue  # a unit that is off answers nothing
                    if "bad_handshake" in unit.faults:
                        code = TcpErrorCode.NO_NODE_AVAILABLE
                        await self.stream.send(encode_node_response(0, unit.number, code))
                        return
                    node = unit.assign_tcp_node()
                    await self.stream.send(encode_node_response(node, unit.number))
                    self.open = True

    async def _write(self) -> None:
        try:
            while True:
                await self.ready.wait()
                self.ready.clear()
                while self.outbox:
                    await self.stream.send(self.outbox.popleft())
        except (anyio.BrokenResourceError, anyio.ClosedResourceError):
            pass  # reset: the reader sees it too
