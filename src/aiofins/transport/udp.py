"""FINS over UDP: one datagram is one FINS frame.

One socket per transport, bound to an ephemeral local port and *connected* to the PLC, so
the kernel drops datagrams from anyone else. The receive buffer is enlarged (best effort) so
that many large replies in flight do not overflow it.

Under stock asyncio a reader callback on the socket drains every queued datagram straight
into the session (asyncio's datagram transport reads one per loop iteration); under uvloop its
own datagram transport calls the session directly (it reads in C); under an asyncio loop
without ``add_reader`` (Windows' default proactor loop) the loop's own datagram endpoint reads
and sends; under any other anyio backend (trio) a reader task drains the socket. The path is
chosen by what the loop can do, not by the platform's name. Under every loop but the proactor
the session may also read the socket right after a send (``poll_now``) when that request is
the only one in flight.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections import deque
from collections.abc import Sized
from typing import TYPE_CHECKING, Any

import anyio

from ..protocol.errors import ConnectionLost
from .base import (
    FrameSink,
    TaskSpawner,
    Transport,
    is_asyncio,
    is_uvloop,
    replies_awaited,
    url_host,
    wrap_os_error,
)

if TYPE_CHECKING:
    from ..memnet import DatagramSocket, MemoryNetwork

DEFAULT_PORT = 9600
#: Receive buffer asked for: room for 50 in-flight 999-word replies many times over.
DEFAULT_RCVBUF = 4 * 1024 * 1024


#: SID spaces (sockets, each with its own source node) a session opens at most by default.
DEFAULT_SID_SPACES = 4

#: Bytes asked of recv(): above the largest FINS frame, so a longer datagram shows as such.
_RECV_SIZE = 4096
#: Datagrams read per readiness callback before yielding to the event loop.
_BATCH = 64


def udp_socket(
    family: int, remote: Any, local_host: str | None, local_port: int, rcvbuf: int
) -> socket.socket:
    """A non-blocking UDP socket of ``family`` with a receive buffer of ``rcvbuf`` asked
    for, bound to ``local_host:local_port`` (any address, an ephemeral port by default) and
    connected to ``remote`` (an address as ``getaddrinfo`` gives it), so the kernel drops
    datagrams from anyone else. Every UDP transport opens its socket here."""
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        sock.setblocking(False)
        # Best effort: Linux caps it at net.core.rmem_max without complaint.
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        local = local_host or ("::" if family == socket.AF_INET6 else "0.0.0.0")
        if local_port:
            # A fixed port (the FINS port, for PLCs that answer to it) is shared by the
            # sockets to several PLCs: each is connected to its PLC, and the kernel hands a
            # datagram to the socket connected to its sender.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((local, local_port))
        sock.connect(remote)
    except BaseException:
        sock.close()
        raise
    return sock


def _drain(recv: Any, sink: FrameSink, awaited: Sized) -> OSError | None:
    """Hand the datagrams queued on the socket (up to :data:`_BATCH`) to the sink.

    Stops early once no reply is awaited (the recv() after the last one would fail). ICMP
    errors (port unreachable) are counted and skipped; another socket error is returned.
    """
    received = sink.frame_received
    left = _BATCH  # (a count, not a range(): no object made per drain)
    while left:
        left -= 1
        try:
            data = recv(_RECV_SIZE)
        except (BlockingIOError, InterruptedError):
            return None
        except ConnectionRefusedError as exc:  # ICMP port unreachable: not fatal for UDP
            sink.frame_dropped(f"socket error: {exc}")
            continue
        except OSError as exc:
            return exc
        received(data)
        if not awaited:
            return None
    return None


class _AsyncioSocket:
    """The asyncio path: one reader callback drains every queued datagram into the sink.

    asyncio's own datagram transport reads one datagram per event-loop iteration; with many
    replies in flight that makes every reply pay a whole iteration (an ``epoll_wait``).
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        sock: socket.socket,
        owner: UdpTransport,
        sink: FrameSink,
    ) -> None:
        self.loop = loop
        self.sock = sock
        self.owner = owner
        self.sink = sink
        self.backlog: deque[bytes] = deque()
        self.awaited = replies_awaited(sink)
        loop.add_reader(sock.fileno(), self.poll)

    def poll(self) -> None:
        """Drain the queued datagrams into the sink: the reader callback, and the
        session's read right after a send."""
        exc = _drain(self.sock.recv, self.sink, self.awaited)
        if exc is not None:
            self.owner._lost(self, exc)

    def send(self, frame: bytes) -> None:
        if self.backlog:
            self.backlog.append(frame)
            return
        try:
            self.sock.send(frame)
        except (BlockingIOError, InterruptedError):  # send buffer full: wait for room
            self.backlog.append(frame)
            self.loop.add_writer(self.sock.fileno(), self._writable)
        except ConnectionRefusedError as exc:  # an earlier ICMP error surfacing here
            self.sink.frame_dropped(f"socket error: {exc}")
        except OSError as exc:
            self.owner._lost(self, exc)
            raise ConnectionLost(f"cannot send to {self.owner.description}: {exc}") from exc

    def _writable(self) -> None:
        backlog = self.backlog
        while backlog:
            try:
                self.sock.send(backlog[0])
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                if not isinstance(exc, ConnectionRefusedError):
                    self.owner._lost(self, exc)
                    return
            backlog.popleft()
        self.loop.remove_writer(self.sock.fileno())

    def close(self) -> None:
        if self.sock.fileno() >= 0:
            self.loop.remove_reader(self.sock.fileno())
            self.loop.remove_writer(self.sock.fileno())
        self.backlog.clear()
        self.sock.close()


class _EndpointProtocol(asyncio.DatagramProtocol):
    """The path through the loop's own datagram endpoint, which reads and calls us.

    Two loops take it: uvloop (it reads in C; ``direct``: we also send and read on our own
    socket object, cheaper than its transport), and a loop without ``add_reader`` (Windows'
    proactor loop: its transport keeps a read of its own outstanding, which a read of ours
    would overtake, and sends through the loop too).
    """

    def __init__(self, owner: UdpTransport, sink: FrameSink, sock: socket.socket, direct: bool):
        self.owner = owner
        self.sink = sink
        self.direct = direct
        self.transport: Any = None  # uvloop's UDPTransport is not an asyncio subclass
        self._raw_send = sock.send  # our own socket object: connected, non-blocking
        self._raw_recv = sock.recv
        self._sock = sock
        self.awaited = replies_awaited(sink)
        self.datagram_received = sink.frame_received  # type: ignore[assignment,method-assign]
        if not direct:
            self.send = self._send_via_loop  # type: ignore[method-assign]

    @property
    def sock(self) -> socket.socket:
        return self._sock

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport

    def send(self, frame: bytes) -> None:
        # The socket is connected: a plain send() is cheaper than uvloop's sendto(), which
        # looks up the address each time. Fall back to the transport if the buffer is full.
        try:
            self._raw_send(frame)
        except (BlockingIOError, InterruptedError):
            self.transport.sendto(frame)
        except ConnectionRefusedError as exc:  # an earlier ICMP error surfacing here
            self.sink.frame_dropped(f"socket error: {exc}")
        except OSError as exc:
            raise ConnectionLost(f"cannot send to {self.owner.description}: {exc}") from exc

    def _send_via_loop(self, frame: bytes) -> None:
        """Send through the loop's transport (it buffers; errors come to error_received)."""
        transport = self.transport
        if transport is None or transport.is_closing():
            raise ConnectionLost(f"{self.owner.description} is closed")
        transport.sendto(frame)

    def poll(self) -> None:
        """Read what has already arrived on the socket (uvloop reads it only at its next pass)."""
        exc = _drain(self._raw_recv, self.sink, self.awaited)
        if exc is not None:  # uvloop's own reader meets it too and reports the loss
            self.sink.frame_dropped(f"socket error: {exc}")

    def error_received(self, exc: Exception) -> None:
        self.sink.frame_dropped(f"socket error: {exc}")  # ICMP unreachable: not fatal

    def connection_lost(self, exc: Exception | None) -> None:
        if self.owner._aio is self:
            self.owner._detach()
            self.sink.connection_lost(exc)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


class _NetworkSocket:
    """The path over an in-memory network (:mod:`aiofins.memnet`): the network calls us when
    a datagram is queued on the socket, and we drain it into the sink as the asyncio path
    drains a real socket (the same :func:`_drain`, ICMP errors included)."""

    def __init__(self, sock: DatagramSocket, owner: UdpTransport, sink: FrameSink) -> None:
        self.sock = sock
        self.owner = owner
        self.sink = sink
        self.awaited = replies_awaited(sink)
        sock.on_readable = self.poll

    def poll(self) -> None:
        """Drain the queued datagrams into the sink: the reader callback, and the
        session's read right after a send."""
        exc = _drain(self.sock.recv, self.sink, self.awaited)
        if exc is not None:
            self.owner._lost(self, exc)

    def send(self, frame: bytes) -> None:
        try:
            self.sock.send(frame)
        except ConnectionRefusedError as exc:  # an earlier ICMP error surfacing here
            self.sink.frame_dropped(f"socket error: {exc}")
        except OSError as exc:
            self.owner._lost(self, exc)
            raise ConnectionLost(f"cannot send to {self.owner.description}: {exc}") from exc

    def close(self) -> None:
        self.sock.on_readable = None
        self.sock.close()


class UdpTransport(Transport):
    """FINS/UDP to ``host:port`` from an ephemeral local port.

    ``network``: an in-memory network (:class:`aiofins.memnet.MemoryNetwork`) instead of the
    operating system's sockets, for tests and simulations (``local_host`` is then our
    address on it; default: the network's ``default_host``).
    """

    reconnectable = True
    own_source_node = True
    default_sid_spaces = DEFAULT_SID_SPACES

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        local_host: str | None = None,
        local_port: int = 0,
        rcvbuf: int = DEFAULT_RCVBUF,
        network: MemoryNetwork | None = None,
    ) -> None:
        self.network = network
        self.host = host
        self.port = port
        self.local_host = local_host
        self.local_port = local_port
        self.rcvbuf = rcvbuf
        self._aio: _AsyncioSocket | _EndpointProtocol | _NetworkSocket | None = None
        self._sock: socket.socket | None = None  # the socket of the anyio (trio) driver

    @property
    def is_open(self) -> bool:
        return self._aio is not None or self._sock is not None

    @property
    def description(self) -> str:
        return f"udp://{url_host(self.host)}:{self.port}"

    @property
    def local_address(self) -> tuple[str, int] | None:
        """``(host, port)`` the socket is bound to, while open."""
        sock = self._aio.sock if self._aio is not None else self._sock
        if sock is None:
            return None
        host, port = sock.getsockname()[:2]
        return str(host), int(port)

    @property
    def peer_link(self) -> str | None:
        """``udp://address:port`` of the peer as the socket is connected to it (a host name
        resolved), while open: what tells two transports' peers apart."""
        sock = self._aio.sock if self._aio is not None else self._sock
        if sock is None:
            return None
        try:
            host, port = sock.getpeername()[:2]
        except OSError:
            return None
        return f"udp://{url_host(str(host))}:{port}"

    def another(self) -> UdpTransport:
        """A UDP transport to the same peer from a socket of its own (another local port):
        its replies come to it alone, once it sends with a source node of its own."""
        return UdpTransport(
            self.host,
            self.port,
            local_host=self.local_host,
            rcvbuf=self.rcvbuf,
            network=self.network,
        )

    async def _socket(self) -> socket.socket:
        """A non-blocking UDP socket, bound to an ephemeral port and connected to the PLC."""
        infos = await anyio.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)
        family, _, _, _, remote = infos[0]
        return udp_socket(family, remote, self.local_host, self.local_port, self.rcvbuf)

    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        if self.is_open:
            return
        if self.network is not None:
            self._open_on_network(self.network, sink)
            return
        try:
            sock = await self._socket()
        except OSError as exc:
            raise wrap_os_error(exc, f"cannot open {self.description}") from exc
        if is_asyncio():
            loop = asyncio.get_running_loop()
            aio: _AsyncioSocket | _EndpointProtocol | None = None
            if not is_uvloop(loop):
                try:
                    aio = _AsyncioSocket(loop, sock, self, sink)
                except NotImplementedError:  # no add_reader (a proactor loop): the endpoint
                    aio = None
            if aio is None:
                direct = is_uvloop(loop)
                proto = _EndpointProtocol(self, sink, sock, direct)
                try:
                    await loop.create_datagram_endpoint(lambda: proto, sock=sock)
                except BaseException:
                    sock.close()
                    raise
                aio = proto
                # Read-after-send only where the loop reads after readiness (uvloop), not
                # where a read of the loop's own is always outstanding (proactor).
                self.poll_now = proto.poll if direct else None
            else:
                self.poll_now = aio.poll
            self._aio = aio
            self.fast_send = aio.send
        else:
            self._sock = sock
            task_group.start_soon(self._reader, sock, sink)
            awaited = replies_awaited(sink)

            def poll() -> None:
                """Read what has already arrived, now (the reader task would wake for it).
                ICMP errors are counted as in the reader; another socket error (none is
                known to occur on a connected datagram socket) is dropped: the request
                then times out."""
                if self._sock is sock:
                    _drain(sock.recv, sink, awaited)

            self.poll_now = poll

    def _open_on_network(self, network: MemoryNetwork, sink: FrameSink) -> None:
        """Open a socket of the in-memory network, connected to the PLC."""
        try:
            sock = network.datagram_socket(
                self.local_host or network.default_host,
                self.local_port,
                remote=(self.host, self.port),
            )
        except OSError as exc:
            raise wrap_os_error(exc, f"cannot open {self.description}") from exc
        aio = self._aio = _NetworkSocket(sock, self, sink)
        self.fast_send = aio.send
        self.poll_now = aio.poll

    async def _reader(self, sock: socket.socket, sink: FrameSink) -> None:
        """The anyio driver: wait until readable, then drain every queued datagram."""
        awaited = replies_awaited(sink)
        exc: BaseException | None = None
        try:
            while True:
                await anyio.wait_readable(sock)
                failure = _drain(sock.recv, sink, awaited)
                if failure is not None:
                    raise failure
        except (anyio.ClosedResourceError, ValueError):
            pass  # closed locally (ValueError: fileno -1)
        except OSError as err:
            exc = err
        if self._sock is sock:
            self._sock = None
            self.poll_now = None
            sock.close()
            sink.connection_lost(exc)

    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        # A datagram socket's send buffer drains without the peer: no wait worth a bound.
        aio = self._aio
        if aio is not None:
            aio.send(frame)
            return
        sock = self._sock
        if sock is None:
            raise ConnectionLost(f"{self.description} is closed")
        while True:
            try:
                sock.send(frame)
                return
            except (BlockingIOError, InterruptedError):  # send buffer full: wait for room
                await anyio.wait_writable(sock)
            except ConnectionRefusedError:  # an earlier ICMP error: the request times out
                return
            except OSError as exc:
                raise wrap_os_error(exc, f"cannot send to {self.description}") from exc

    def _detach(self) -> None:
        """No asyncio socket any more: the session's synchronous paths go too."""
        self._aio = None
        self.fast_send = None
        self.poll_now = None

    def _lost(
        self, aio: _AsyncioSocket | _EndpointProtocol | _NetworkSocket, exc: BaseException
    ) -> None:
        if self._aio is aio:
            self._detach()
            aio.close()
            aio.sink.connection_lost(exc)

    async def aclose(self) -> None:
        aio, sock = self._aio, self._sock
        self._detach()  # poll_now too
        self._sock = None
        if aio is not None:
            aio.close()
        if sock is not None:
            anyio.notify_closing(sock)  # wake the reader before the socket goes away
            sock.close()
