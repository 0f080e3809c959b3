"""An in-memory network: hosts by address, datagram sockets, byte streams, a fault hook.

A bottom-layer module (it imports anyio and the standard library only), so that both the
transports (:class:`~aiofins.transport.UdpTransport` and
:class:`~aiofins.transport.TcpTransport` take ``network=``) and the simulator's servers
(``UdpServer(..., network=)``, ``TcpServer(..., network=)``) run their real code over it
without a socket, under asyncio (a virtual-time loop included) and trio (``MockClock``
included)::

    async with MemoryNetwork() as net:
        async with run_simulator(plc, udp=("10.0.0.5", 9600), network=net):
            transport = UdpTransport("10.0.0.5", local_host="10.0.0.1", network=net)
            ...

Addresses are ``(host, port)`` with the host a string (``"10.0.0.5"``); a socket bound to
``"0.0.0.0"`` (or ``""``) receives datagrams for any host on its port, and sends from
:attr:`MemoryNetwork.default_host`. Port 0 takes the next free ephemeral port (49152 up, in
order: the same run gives the same ports).

**Delivery.** What is sent is not handed over inside the send: each unit (a
:class:`Packet`: a datagram, a chunk of a byte stream, a connection request) is put on the
wire, and the network's delivery task hands it over when it is due, in order of due time and
then of sending. Time is the event loop's (``anyio.current_time()``), so under a virtual
clock a delay costs no wall time and is exact. A datagram goes into the receiving socket's
queue (as into a kernel's receive buffer) and the socket's ``on_readable`` callback, if any,
is called; a stream chunk into the stream's buffer.

**The fault hook.** ``net.fate`` (``None``: everything delivered after ``net.latency``
seconds) is called once per packet sent and returns the delays after which it arrives::

    def fate(packet: Packet) -> Sequence[float]:
        ...

- a datagram: ``[]`` drops it, ``[0.0]`` delivers it after no delay, ``[0.0, 0.3]``
  delivers it and a duplicate 0.3 s later; reordering is a longer delay for one than for
  the next;
- a stream chunk (``packet.kind == "stream"``): ``[]`` resets the connection (both ends
  see it broken, what is buffered is lost); ``[d]`` delivers it after ``d``; ``[d1, d2, ...]``
  splits it into that many pieces, delivered at those delays. A stream keeps its order
  (a piece never overtakes an earlier one: its delay is raised to the previous piece's);
- a connection request (``packet.kind == "connect"``, no data): ``[]`` loses it (the
  caller's connect waits until its own timeout), ``[d]`` establishes it after ``d``.

The hook may be replaced at any time (a fault schedule changes it as its world moves on).
``net.reset(stream)`` resets one connection at once; ``net.streams`` lists the open ones.

**Bounds and boundaries.** Every queue is bounded: the wire (``max_queued`` packets; beyond,
a packet is dropped), each datagram socket's receive queue (``rcvbuf`` datagrams; beyond,
dropped, as a kernel does), each stream direction (``stream_buffer`` bytes buffered or in
flight: a sender waits for room, as TCP's window makes it), each listener's backlog (beyond,
connections are refused). Nothing raised by the fault hook or a socket's callback escapes a
delivery: it is logged and counted (:class:`NetworkStats`), and the packet is dropped (the
hook's) or counted as delivered (a callback's). Every drop is counted by its reason.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import logging
import socket
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Literal

import anyio
from anyio.abc import ByteStream, SocketAttribute, TaskGroup

__all__ = [
    "Address",
    "DatagramSocket",
    "Fate",
    "MemoryNetwork",
    "MemoryStream",
    "NetworkStats",
    "Packet",
    "StreamListener",
]

logger = logging.getLogger("aiofins.memnet")

#: ``(host, port)``.
Address = tuple[str, int]
#: What a unit the network carries is: a datagram, a chunk of a byte stream, a connection
#: request.
PacketKind = Literal["datagram", "stream", "connect"]

#: Ephemeral ports, taken in order.
EPHEMERAL_PORTS = (49152, 65535)
_ANY_HOSTS = ("", "0.0.0.0", "::")


@dataclass(frozen=True, slots=True)
class Packet:
    """One unit the network carries, as the fault hook sees it."""

    #: ``"datagram"``, ``"stream"`` (a chunk of a byte stream) or ``"connect"``.
    kind: PacketKind
    #: Where it comes from and goes to.
    source: Address
    dest: Address
    #: Its bytes (empty for a connection request).
    data: bytes
    #: The network's count of packets sent, this one included (1, 2, ...): the same run
    #: numbers them the same way.
    number: int


#: The fault hook: the delays after which a packet arrives (see the module's docstring).
Fate = Callable[[Packet], Sequence[float]]


@dataclass(slots=True)
class NetworkStats:
    """What the network carried and why anything was lost."""

    #: Packets put on the wire (datagrams, stream chunks, connection requests).
    sent: int = 0
    #: Copies handed over (a duplicate counts twice).
    delivered: int = 0
    #: Packets the fault hook dropped, extra copies it made, connections it reset.
    dropped: int = 0
    duplicated: int = 0
    resets: int = 0
    #: Datagrams for a port nobody is bound to (a connected sender is told, as by ICMP).
    unreachable: int = 0
    #: Datagrams a connected socket did not take (from another address than its peer).
    filtered: int = 0
    #: Dropped for want of room: the wire full, a receive queue full.
    overflows: int = 0
    #: Connection requests refused (no listener, its backlog full).
    refused: int = 0
    #: Exceptions raised by the fault hook or a socket's callback (logged).
    hook_errors: int = 0
    callback_errors: int = 0


class DatagramSocket:
    """A UDP-like socket on a :class:`MemoryNetwork`.

    Both a non-blocking socket's calls (``recv`` raising :class:`BlockingIOError` when
    nothing is queued, ``send`` on a connected socket, ``getsockname``, ``getpeername``) with
    an ``on_readable`` callback, for a transport's synchronous path, and anyio's
    ``UDPSocket`` calls (``await receive()``, ``await sendto(data, host, port)``), for a
    server's loop.
    """

    def __init__(self, network: MemoryNetwork, local: Address, remote: Address | None) -> None:
        self.network = network
        self.local = local
        #: The peer of a connected socket: datagrams from anyone else are not taken.
        self.remote = remote
        #: Called (synchronously, from the delivery task) when a datagram was queued.
        self.on_readable: Callable[[], None] | None = None
        self.closed = False
        self._queue: deque[tuple[bytes, Address]] = deque()
        self._error: OSError | None = None  # an ICMP error, raised by the next recv()
        self._arrived: anyio.Event | None = None

    def __repr__(self) -> str:
        return f"<DatagramSocket {self.local} -> {self.remote}>"

    # -- a non-blocking socket's calls -----------------------------------------------------

    def getsockname(self) -> Address:
        return self.local

    def getpeername(self) -> Address:
        if self.remote is None:
            raise OSError("not connected")
        return self.remote

    def recv(self, bufsize: int) -> bytes:
        """The next queued datagram (cut to ``bufsize``, as a kernel cuts it)."""
        if self.closed:
            raise OSError("socket is closed")
        error = self._error
        if error is not None:
            self._error = None
            raise error
        if not self._queue:
            raise BlockingIOError("no datagram queued")
        return self._queue.popleft()[0][:bufsize]

    def recvfrom(self, bufsize: int) -> tuple[bytes, Address]:
        if self.closed:
            raise OSError("socket is closed")
        if not self._queue:
            raise BlockingIOError("no datagram queued")
        data, source = self._queue.popleft()
        return data[:bufsize], source

    def send(self, data: bytes) -> int:
        """Send to the connected peer."""
        if self.remote is None:
            raise OSError("not connected")
        return self.sendto(data, self.remote)

    def sendto(self, data: bytes, address: Address) -> int:
        if self.closed:
            raise OSError("socket is closed")
        host, port = address
        self.network._transmit("datagram", self.local, (host, int(port)), bytes(data), self)
        return len(data)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._queue.clear()
            self.network._unbind(self)
            self._wake()

    # -- anyio's UDPSocket calls -----------------------------------------------------------

    async def receive(self) -> tuple[bytes, Address]:
        """The next datagram and its sender, waiting for one."""
        while True:
            if self.closed:
                raise anyio.ClosedResourceError
            if self._queue:
                return self._queue.popleft()
            error = self._error
            if error is not None:
                self._error = None
                raise error
            arrived = self._arrived = anyio.Event()
            await arrived.wait()

    async def send_to(self, data: bytes, host: str, port: int) -> None:
        self.sendto(data, (host, port))

    async def aclose(self) -> None:
        self.close()

    @property
    def local_address(self) -> Address:
        return self.local

    # -- the network's side ----------------------------------------------------------------

    def _deliver(self, data: bytes, source: Address) -> None:
        network = self.network
        if self.remote is not None and source != self.remote:
            network.stats.filtered += 1
            return
        if len(self._queue) >= network.rcvbuf:
            network.stats.overflows += 1
            return
        self._queue.append((data, source))
        network.stats.delivered += 1
        self._wake()

    def _refused(self) -> None:
        """The peer's port is not bound (an ICMP port unreachable, to a connected socket)."""
        self._error = ConnectionRefusedError("port unreachable")
        self._wake()

    def _wake(self) -> None:
        arrived, self._arrived = self._arrived, None
        if arrived is not None:
            arrived.set()
        callback = self.on_readable
        if callback is not None:
            try:
                callback()
            except Exception:  # a boundary: never out of a delivery
                self.network.stats.callback_errors += 1
                logger.exception("memnet: on_readable of %r failed", self)


class _Direction:
    """One direction of a byte stream: what was sent and not yet received, bounded."""

    __slots__ = ("arrived", "buffer", "eof", "last_due", "outstanding", "room", "shut")

    def __init__(self) -> None:
        self.buffer = bytearray()
        #: The sender sent its end (``shut``); it arrived after the bytes before it (``eof``).
        self.shut = False
        self.eof = False
        self.arrived: anyio.Event | None = None
        self.room: anyio.Event | None = None
        #: Bytes on the wire or in the buffer (the window).
        self.outstanding = 0
        #: When the last piece sent this way is due (pieces never overtake each other).
        self.last_due = 0.0

    def wake_reader(self) -> None:
        arrived, self.arrived = self.arrived, None
        if arrived is not None:
            arrived.set()

    def wake_writer(self) -> None:
        room, self.room = self.room, None
        if room is not None:
            room.set()


class MemoryStream(ByteStream):
    """One end of a TCP-like connection on a :class:`MemoryNetwork` (an anyio
    ``ByteStream``; ``extra(SocketAttribute.remote_address)`` and the like work)."""

    def __init__(
        self, network: MemoryNetwork, local: Address, remote: Address, inbound: _Direction
    ) -> None:
        self.network = network
        self.local = local
        self.remote = remote
        self._in = inbound
        self._out = _Direction()
        self.peer: MemoryStream | None = None
        self.closed = False
        #: Reset (by the fault hook or :meth:`MemoryNetwork.reset`): both ends are broken.
        self.broken = False

    def __repr__(self) -> str:
        return f"<MemoryStream {self.local} -> {self.remote}>"

    @property
    def extra_attributes(self) -> Mapping[Any, Callable[[], Any]]:
        return {
            SocketAttribute.family: lambda: socket.AF_INET,
            SocketAttribute.local_address: lambda: self.local,
            SocketAttribute.local_port: lambda: self.local[1],
            SocketAttribute.remote_address: lambda: self.remote,
            SocketAttribute.remote_port: lambda: self.remote[1],
        }

    async def receive(self, max_bytes: int = 65536) -> bytes:
        inbound = self._in
        while True:
            if self.closed:
                raise anyio.ClosedResourceError
            if self.broken:
                raise anyio.BrokenResourceError("connection reset")
            if inbound.buffer:
                data = bytes(inbound.buffer[:max_bytes])
                del inbound.buffer[:max_bytes]
                inbound.outstanding -= len(data)
                inbound.wake_writer()
                return data
            if inbound.eof:
                raise anyio.EndOfStream
            arrived = inbound.arrived = anyio.Event()
            await arrived.wait()

    async def send(self, item: bytes) -> None:
        out = self._out
        limit = self.network.stream_buffer
        while True:
            if self.closed:
                raise anyio.ClosedResourceError
            if self.broken or out.shut:
                raise anyio.BrokenResourceError("connection reset" if self.broken else "EOF sent")
            if not out.outstanding or out.outstanding + len(item) <= limit:
                break
            room = out.room = anyio.Event()
            await room.wait()
        if item:
            out.outstanding += len(item)
            self.network._transmit("stream", self.local, self.remote, bytes(item), self)

    async def send_eof(self) -> None:
        if not (self.closed or self.broken or self._out.shut):
            self._out.shut = True
            self.network._schedule_eof(self)

    async def aclose(self) -> None:
        self.close()

    def close(self) -> None:
        if self.closed:
            return
        if not self.broken and not self._out.shut:
            self._out.shut = True
            self.network._schedule_eof(self)
        self.closed = True
        self._in.wake_reader()
        self._out.wake_writer()
        self.network._forget(self)

    def _break(self) -> None:
        self.broken = True
        self._in.buffer.clear()
        self._in.wake_reader()
        self._out.wake_writer()


class StreamListener:
    """Accepts connections to one address of a :class:`MemoryNetwork` (see
    :meth:`MemoryNetwork.listen`)."""

    def __init__(self, network: MemoryNetwork, local: Address, backlog: int) -> None:
        self.network = network
        self.local = local
        self.backlog = backlog
        self.closed = False
        self._queue: deque[MemoryStream] = deque()
        self._arrived: anyio.Event | None = None

    @property
    def port(self) -> int:
        return self.local[1]

    async def accept(self) -> MemoryStream:
        while True:
            if self.closed:
                raise anyio.ClosedResourceError
            if self._queue:
                return self._queue.popleft()
            arrived = self._arrived = anyio.Event()
            await arrived.wait()

    async def aclose(self) -> None:
        self.close()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.network._unlisten(self)
            for stream in self._queue:  # never accepted: their clients see a reset
                self.network.reset(stream)
            self._queue.clear()
            arrived, self._arrived = self._arrived, None
            if arrived is not None:
                arrived.set()

    def _offer(self, stream: MemoryStream) -> bool:
        if self.closed or len(self._queue) >= self.backlog:
            return False
        self._queue.append(stream)
        arrived, self._arrived = self._arrived, None
        if arrived is not None:
            arrived.set()
        return True


@dataclass(order=True, slots=True)
class _Due:
    at: float
    seq: int
    what: Callable[[], None] = field(compare=False)


def _loop_clock() -> Callable[[], float]:
    """The running backend's clock, callable from its callbacks too (asyncio's loop.time)."""
    try:
        return asyncio.get_running_loop().time
    except RuntimeError:
        return anyio.current_time


class MemoryNetwork:
    """A network in this process (see the module's docstring). Use as
    ``async with MemoryNetwork() as net:``: the delivery task runs inside.

    ``fate``: the fault hook (``None``: every packet after ``latency`` seconds);
    ``default_host``: the address of a socket bound to ``"0.0.0.0"``; ``max_queued``,
    ``rcvbuf`` (datagrams per socket) and ``stream_buffer`` (bytes per stream direction):
    the bounds.
    """

    def __init__(
        self,
        *,
        fate: Fate | None = None,
        latency: float = 0.0,
        default_host: str = "127.0.0.1",
        max_queued: int = 65536,
        rcvbuf: int = 4096,
        stream_buffer: int = 1 << 20,
    ) -> None:
        self.fate = fate
        self.latency = latency
        self.default_host = default_host
        self.max_queued = max_queued
        self.rcvbuf = rcvbuf
        self.stream_buffer = stream_buffer
        self.stats = NetworkStats()
        #: Open byte streams (both ends of each connection).
        self.streams: list[MemoryStream] = []
        self._datagram: dict[Address, DatagramSocket] = {}
        self._listeners: dict[Address, StreamListener] = {}
        self._ports = itertools.count(EPHEMERAL_PORTS[0])
        self._numbers = itertools.count(1)
        self._seq = itertools.count()
        self._heap: list[_Due] = []
        self._wake: anyio.Event | None = None
        self._tg: TaskGroup | None = None
        #: The event loop's clock (anyio.current_time() needs a task: a send from an asyncio
        #: callback, such as a batch's flush or the Poller's timer, has none).
        self._now: Callable[[], float] = anyio.current_time

    # -- lifecycle ---------------------------------------------------------------------------

    async def __aenter__(self) -> MemoryNetwork:
        self._now = _loop_clock()
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        tg.start_soon(self._run)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        tg, self._tg = self._tg, None
        if tg is not None:
            tg.cancel_scope.cancel()
            await tg.__aexit__(None, None, None)
        self._heap.clear()
        return None

    async def _run(self) -> None:
        """The delivery task: hands over each packet when it is due."""
        heap = self._heap
        while True:
            now = self._now()
            while heap and heap[0].at <= now:
                due = heapq.heappop(heap)
                try:
                    due.what()
                except Exception:  # a boundary: a bug here loses one packet, not the network
                    self.stats.callback_errors += 1
                    logger.exception("memnet: a delivery failed")
            wake = self._wake = anyio.Event()
            if heap:
                with anyio.CancelScope(deadline=heap[0].at):
                    await wake.wait()
            else:
                await wake.wait()

    # -- datagrams ---------------------------------------------------------------------------

    def datagram_socket(
        self,
        local_host: str | None = None,
        local_port: int = 0,
        remote: Address | None = None,
    ) -> DatagramSocket:
        """A datagram socket bound to ``(local_host, local_port)`` (port 0: an ephemeral
        one), connected to ``remote`` if given. An address in use raises ``OSError``."""
        self._running()
        host = local_host or "0.0.0.0"
        port = local_port or self._ephemeral(host)
        if (host, port) in self._datagram:
            raise OSError(f"address {host}:{port} already in use")
        sock = DatagramSocket(self, (host, port), remote)
        self._datagram[(host, port)] = sock
        return sock

    def _running(self) -> None:
        if self._tg is None:
            raise RuntimeError(
                "the network is not running: use 'async with MemoryNetwork() as net'"
            )

    def _ephemeral(self, host: str) -> int:
        for _ in range(EPHEMERAL_PORTS[1] - EPHEMERAL_PORTS[0] + 1):
            port = next(self._ports)
            if port > EPHEMERAL_PORTS[1]:
                self._ports = itertools.count(EPHEMERAL_PORTS[0] + 1)
                port = EPHEMERAL_PORTS[0]
            if (host, port) not in self._datagram and (host, port) not in self._listeners:
                return port
        raise OSError("no free ephemeral port")

    def _unbind(self, sock: DatagramSocket) -> None:
        if self._datagram.get(sock.local) is sock:
            del self._datagram[sock.local]

    def _find(self, dest: Address) -> DatagramSocket | None:
        sock = self._datagram.get(dest)
        if sock is None:
            for any_host in _ANY_HOSTS:
                sock = self._datagram.get((any_host, dest[1]))
                if sock is not None:
                    break
        return sock

    # -- streams -----------------------------------------------------------------------------

    def listen(self, host: str, port: int = 0, *, backlog: int = 16) -> StreamListener:
        """A listener on ``(host, port)`` (port 0: an ephemeral one)."""
        self._running()
        host = host or "0.0.0.0"
        port = port or self._ephemeral(host)
        if (host, port) in self._listeners:
            raise OSError(f"address {host}:{port} already in use")
        listener = StreamListener(self, (host, port), backlog)
        self._listeners[(host, port)] = listener
        return listener

    def _unlisten(self, listener: StreamListener) -> None:
        if self._listeners.get(listener.local) is listener:
            del self._listeners[listener.local]

    async def connect(self, host: str, port: int, *, local_host: str | None = None) -> MemoryStream:
        """A connection to the listener on ``(host, port)``: ``ConnectionRefusedError`` if
        there is none (or its backlog is full); waits as long as the fault hook delays the
        request (for ever if it loses it: bound it with the caller's timeout). A duplicate of
        the request, or one arriving after the caller gave up, makes no connection."""
        self._running()
        local = (local_host or self.default_host, self._ephemeral(local_host or "0.0.0.0"))
        dest = (host, int(port))
        done = anyio.Event()
        result: list[MemoryStream | OSError] = []

        def establish() -> None:
            if done.is_set():  # a duplicate, or the caller gave up
                return
            listener = self._listeners.get(dest)
            if listener is None:
                for any_host in _ANY_HOSTS:
                    listener = self._listeners.get((any_host, dest[1]))
                    if listener is not None:
                        break
            if listener is None or listener.closed:
                self.stats.refused += 1
                result.append(ConnectionRefusedError(f"{host}:{port}: connection refused"))
            else:
                a_to_b, b_to_a = _Direction(), _Direction()
                client = MemoryStream(self, local, dest, b_to_a)
                server = MemoryStream(self, dest, local, a_to_b)
                client._out, server._out = a_to_b, b_to_a
                client.peer, server.peer = server, client
                if listener._offer(server):
                    self.streams += [client, server]
                    self.stats.delivered += 1
                    result.append(client)
                else:
                    self.stats.refused += 1
                    result.append(ConnectionRefusedError(f"{host}:{port}: backlog full"))
            done.set()

        self._put("connect", local, dest, b"", establish)
        try:
            await done.wait()
        except BaseException:  # cancelled (a timeout): no connection is left behind
            done.set()
            if result and isinstance(result[0], MemoryStream):
                self.reset(result[0])
            raise
        got = result[0]
        if isinstance(got, OSError):
            raise got
        return got

    def reset(self, stream: MemoryStream) -> None:
        """Reset ``stream``'s connection now: both ends broken, buffered bytes lost."""
        if stream.broken:
            return
        self.stats.resets += 1
        for end in (stream, stream.peer):
            if end is not None:
                end._break()
                self._forget(end)

    def _forget(self, stream: MemoryStream) -> None:
        if stream in self.streams:
            self.streams.remove(stream)

    def _schedule_eof(self, stream: MemoryStream) -> None:
        out = stream._out
        at = max(self._now(), out.last_due)

        def arrive() -> None:
            out.eof = True
            out.wake_reader()

        self._push(at, arrive)

    # -- the wire ----------------------------------------------------------------------------

    def _transmit(
        self,
        kind: PacketKind,
        source: Address,
        dest: Address,
        data: bytes,
        sender: DatagramSocket | MemoryStream,
    ) -> None:
        """Put one datagram or stream chunk on the wire, as the fault hook decides."""
        if source[0] in _ANY_HOSTS:
            source = (self.default_host, source[1])
        if kind == "datagram":
            assert isinstance(sender, DatagramSocket)
            self._put(kind, source, dest, data, lambda: self._arrive(data, source, dest, sender))
            return
        assert isinstance(sender, MemoryStream)
        delays = self._fate(kind, source, dest, data)
        if delays is None:
            return
        if not delays:
            self.stats.dropped += 1
            self.reset(sender)
            return
        out = sender._out
        now = self._now()
        pieces = _split(data, len(delays))
        for piece, delay in zip(pieces, delays, strict=True):
            at = max(now + max(delay, 0.0), out.last_due)
            out.last_due = at

            def arrive(piece: bytes = piece) -> None:
                if sender.broken:
                    return
                out.buffer += piece
                self.stats.delivered += 1
                out.wake_reader()

            self._push(at, arrive)

    def _put(
        self,
        kind: PacketKind,
        source: Address,
        dest: Address,
        data: bytes,
        what: Callable[[], None],
    ) -> None:
        """A datagram or connection request: each copy the fault hook asks for."""
        delays = self._fate(kind, source, dest, data)
        if delays is None:
            return
        if not delays:
            self.stats.dropped += 1
            return
        self.stats.duplicated += len(delays) - 1
        now = self._now()
        for delay in delays:
            self._push(now + max(delay, 0.0), what)

    def _fate(
        self, kind: PacketKind, source: Address, dest: Address, data: bytes
    ) -> Sequence[float] | None:
        """The delays the fault hook gives a packet (``None``: it raised; dropped)."""
        self.stats.sent += 1
        number = next(self._numbers)
        fate = self.fate
        if fate is None:
            return (self.latency,)
        try:
            return list(fate(Packet(kind, source, dest, data, number)))
        except Exception:  # a boundary: a bad hook drops the packet, it raises nowhere
            self.stats.hook_errors += 1
            self.stats.dropped += 1
            logger.exception("memnet: the fault hook failed on packet %d", number)
            return None

    def _push(self, at: float, what: Callable[[], None]) -> None:
        if len(self._heap) >= self.max_queued:
            self.stats.overflows += 1
            return
        heapq.heappush(self._heap, _Due(at, next(self._seq), what))
        wake = self._wake
        if wake is not None:
            wake.set()

    def _arrive(self, data: bytes, source: Address, dest: Address, sender: DatagramSocket) -> None:
        sock = self._find(dest)
        if sock is None or sock.closed:
            self.stats.unreachable += 1
            if sender.remote == dest and not sender.closed:
                sender._refused()
            return
        sock._deliver(data, source)


def _split(data: bytes, n: int) -> list[bytes]:
    """``data`` in ``n`` pieces as equal as can be (some empty if ``n`` exceeds its size)."""
    size, extra = divmod(len(data), n)
    out, at = [], 0
    for i in range(n):
        end = at + size + (1 if i < extra else 0)
        out.append(data[at:end])
        at = end
    return out
