"""FINS/TCP: a 16-byte envelope per message, a node-address handshake per connection.

The protocol itself (handshake, framing, every field checked) is
:class:`~aiofins.protocol.tcp.TcpClientConnection`, without I/O; this module only pumps bytes
between it and a socket, under asyncio and under any anyio backend. After connecting we send
our client node (0 = "allocate one for me") and wait for the
server's reply, which names our node and the server's; both are exposed as
:attr:`TcpTransport.local_node` and :attr:`TcpTransport.remote_node`. The session uses the
allocated node as SA1. Command 3 (error notification) ends the connection with
:class:`FinsTcpError`; command 6 (connection confirmation) is discarded. The socket is closed
on every path out (a leaked connection holds one of the PLC's node slots).

Under asyncio (stock or uvloop) an asyncio protocol hands frames to the session from
``data_received`` and sends synchronously: a frame alone in flight at once, frames sent while
others are in flight gathered into one write per event-loop step. We make and connect the
socket ourselves, so the session can read what already arrived right after a send
(``poll_now``, into the same connection). Under trio a reader task waits on the stream's socket
and reads it (the session's ``poll_now`` reads it too, into the same connection), and each frame
is written on its own.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import Sequence
from typing import TYPE_CHECKING, cast

import anyio
from anyio.abc import ByteStream, SocketAttribute, SocketStream

from ..protocol.errors import ConnectionLost, FinsError, FinsTimeout, FrameError
from ..protocol.tcp import (
    DEFAULT_PORT,
    MAX_NODE,
    FrameReceived,
    MessageDiscarded,
    NodeAssigned,
    PeerError,
    TcpClientConnection,
    TcpConnectionState,
    TcpEvent,
    encode_frame,
    encode_frames,
)
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
    from ..memnet import MemoryNetwork

#: Seconds a connection attempt (TCP connect and node-address handshake) may take.
DEFAULT_CONNECT_TIMEOUT = 5.0
#: FINS/TCP connections a session opens to one PLC at most by default (each holds one of
#: the Ethernet unit's client nodes: a CS1W/CJ1W-ETN21 has 16, 239-254, for all its clients).
DEFAULT_SID_SPACES = 2
#: Bytes asked of one read-after-send recv(): a few replies of the largest FINS frame.
_RECV_SIZE = 65536


_OPEN = TcpConnectionState.OPEN


class _TcpProtocol(asyncio.Protocol):
    """The asyncio pump: bytes from ``data_received`` into the connection, frames from it
    straight to the session."""

    def __init__(self, owner: TcpTransport, sink: FrameSink) -> None:
        self.owner = owner
        self.sink = sink
        self.conn = TcpClientConnection(owner.node)
        self.received = sink.frame_received
        self.handshake: asyncio.Future[tuple[int, int]] = asyncio.get_running_loop().create_future()
        self.transport: asyncio.Transport | None = None
        self.outbox: list[bytes] = []
        self.gather = owner.gather_writes
        self.awaited = replies_awaited(sink)
        self.loop = asyncio.get_running_loop()
        #: Our own handle on the connected socket (the transport's is not readable).
        self.sock: socket.socket | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not ``isinstance(transport, asyncio.Transport)``: uvloop's TCPTransport has the
        # same methods but is not a subclass of asyncio's.
        self.transport = cast(asyncio.Transport, transport)

    def send(self, frame: bytes) -> None:
        """Write ``frame`` now if its request is the only one in flight, else at the end of
        this event-loop step together with the other frames sent in it (one system call for
        many frames; order kept)."""
        transport = self.transport
        if transport is None or transport.is_closing():
            raise ConnectionLost(f"{self.owner.description} is not connected")
        outbox = self.outbox
        if outbox:
            outbox.append(encode_frame(frame))
        elif self.gather and len(self.awaited) > 1:
            outbox.append(encode_frame(frame))
            self.loop.call_soon(self.flush)
        else:
            transport.write(encode_frame(frame))

    def send_many(self, frames: list[bytes]) -> None:
        """Write ``frames`` in one write (behind frames gathered earlier in this step)."""
        transport = self.transport
        if transport is None or transport.is_closing():
            raise ConnectionLost(f"{self.owner.description} is not connected")
        if not self.gather:
            for frame in frames:
                transport.write(encode_frame(frame))
            return
        data = encode_frames(frames)
        if self.outbox:
            self.outbox.append(data)
        else:
            transport.write(data)

    def flush(self) -> None:
        """Write the frames gathered in the last event-loop step, as one write."""
        outbox = self.outbox
        self.outbox = []
        transport = self.transport
        if outbox and transport is not None and not transport.is_closing():
            transport.write(b"".join(outbox))

    def poll(self) -> None:
        """Read what has already arrived on the socket, now (the transport would read it at
        its next loop pass). The end of the stream or a socket error is left for the
        transport's own reader to meet and report."""
        sock = self.sock
        if sock is None:
            return
        try:
            data = sock.recv(_RECV_SIZE)
        except OSError:  # nothing yet (BlockingIOError), or an error the transport will see
            return
        if data:
            self.data_received(data)

    def data_received(self, data: bytes) -> None:
        if self.conn.state is not _OPEN:
            self.before_handshake(data)
            return
        try:
            events = self.conn.receive_data(data, self.received)
            error = deliver(self.owner, events, self.sink) if events else None
        except FrameError as exc:
            error = exc
        if error is not None:
            self.fail(error)

    def before_handshake(self, data: bytes) -> None:
        try:
            nodes, early = handshake_step(self.owner, self.conn, data)
        except FrameError as exc:
            self.fail(exc)
            return
        if nodes is None:
            return
        if not self.handshake.done():  # (cancelled: the connect gave up and closes us)
            self.handshake.set_result(nodes)
        error = deliver(self.owner, early, self.sink)
        if error is not None:
            self.fail(error)

    def fail(self, exc: BaseException) -> None:
        """End the connection: the stream is unusable after a framing error or command 3."""
        self.conn.close()
        if not self.handshake.done():
            self.handshake.set_exception(exc)
        elif self.owner._aio is self:
            self.owner._detach()
            self.sink.connection_lost(exc)
        if self.transport is not None:
            self.transport.close()

    def connection_lost(self, exc: Exception | None) -> None:
        lost = ConnectionLost(f"{self.owner.description} closed the connection")
        lost.__cause__ = exc
        self.fail(lost)


def handshake_step(
    owner: Transport, conn: TcpClientConnection, data: bytes
) -> tuple[tuple[int, int] | None, list[TcpEvent]]:
    """Feed bytes read during the handshake to ``conn``: ``(client node, server node)`` once
    assigned (else ``None``) and the events that followed the assignment in ``data``.

    A refused handshake raises :class:`FinsTcpError`; a reply that breaks the protocol (a
    node out of 1..254, a FINS frame first, ...) :class:`FrameError`.
    """
    try:
        events = conn.receive_data(data)
    except FrameError as exc:  # the same error, naming the peer (its class and fields kept)
        exc.args = (f"{owner.description}: {exc}", *exc.args[1:])
        raise
    for i, event in enumerate(events):
        if isinstance(event, PeerError):
            raise event.error(owner.description)
        if isinstance(event, NodeAssigned):
            return (event.client_node, event.server_node), list(events[i + 1 :])
    return None, []


def deliver(owner: Transport, events: Sequence[TcpEvent], sink: FrameSink) -> FrameError | None:
    """Hand the events after the handshake to the sink, in order; the error that ends the
    connection, if any.

    A FINS frame goes to the session, a connection confirmation is discarded, an error
    notification (command 3) comes back as :class:`FinsTcpError` (the connection is over),
    and any other message is dropped and counted.
    """
    for event in events:
        if isinstance(event, FrameReceived):
            sink.frame_received(event.frame)
        elif isinstance(event, PeerError):
            return event.error(owner.description)
        elif isinstance(event, MessageDiscarded):
            sink.frame_dropped(event.reason)
    return None


async def _connect(loop: asyncio.AbstractEventLoop, host: str, port: int) -> socket.socket:
    """A connected, non-blocking TCP socket to the first address of ``host`` that accepts."""
    infos = await loop.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    error: OSError = OSError(f"no address found for {host!r}")
    for family, kind, proto, _, address in infos:
        sock = socket.socket(family, kind, proto)
        try:
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            await loop.sock_connect(sock, address)
        except OSError as exc:
            sock.close()
            error = exc
            continue
        except BaseException:
            sock.close()
            raise
        return sock
    raise error


class TcpTransport(Transport):
    """FINS/TCP to ``host:port``; ``node`` 0 lets the PLC allocate our node.

    ``network``: an in-memory network (:class:`aiofins.memnet.MemoryNetwork`) instead of the
    operating system's sockets, for tests and simulations: the same handshake and framing
    over its byte stream, read by a reader task and written frame by frame under every
    backend (``local_host``: our address on it; default: the network's ``default_host``).
    """

    reconnectable = True
    fresh_sid_space = True
    default_sid_spaces = DEFAULT_SID_SPACES
    reliable = True

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        node: int = 0,
        connect_timeout: float = DEFAULT_CONNECT_TIMEOUT,
        gather_writes: bool = True,
        network: MemoryNetwork | None = None,
        local_host: str | None = None,
    ) -> None:
        if not 0 <= node <= MAX_NODE:
            raise FrameError(f"FINS/TCP client node {node} out of range 0..{MAX_NODE}")
        self.host = host
        self.port = port
        #: The client node we ask for in the handshake (0 = let the server allocate).
        self.node = node
        self.connect_timeout = connect_timeout
        #: Under asyncio, write the frames sent in one event-loop step together (one system
        #: call). ``False`` writes each frame on its own, for a peer whose TCP stack mishandles
        #: several FINS/TCP messages in one segment (TCP itself may still join them).
        self.gather_writes = gather_writes
        self.network = network
        self.local_host = local_host
        #: The connection over an in-memory network, while open.
        self._mem: ByteStream | None = None
        self._stream: SocketStream | None = None
        self._raw: socket.socket | None = None  # the stream's socket (trio path)
        self._sink: FrameSink | None = None  # whom the trio path reports to
        self._aio: _TcpProtocol | None = None
        self._send_lock = anyio.Lock()
        self.local_node: int | None = None
        self.remote_node: int | None = None

    @property
    def is_open(self) -> bool:
        return self._stream is not None or self._aio is not None or self._mem is not None

    @property
    def description(self) -> str:
        return f"tcp://{url_host(self.host)}:{self.port}"

    def another(self) -> TcpTransport:
        """Another FINS/TCP connection to the same PLC, its node allocated by the PLC (a fixed
        ``node`` is held by this connection: the PLC would refuse it to a second one)."""
        return TcpTransport(
            self.host,
            self.port,
            connect_timeout=self.connect_timeout,
            gather_writes=self.gather_writes,
            network=self.network,
            local_host=self.local_host,
        )

    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        if self.is_open:
            return
        if self.network is not None:
            await self._open_on_network(self.network, sink, task_group)
            return
        if is_asyncio():
            await self._open_asyncio(sink)
            return
        conn = TcpClientConnection(self.node)
        stream: SocketStream | None = None
        try:
            with anyio.fail_after(self.connect_timeout):  # connect and handshake
                stream = await anyio.connect_tcp(self.host, self.port)
                early = await self._handshake(stream, conn)
        except BaseException as exc:
            if stream is not None:
                with anyio.CancelScope(shield=True):
                    await stream.aclose()
            raise self._open_failed(exc) from exc
        self._stream = stream
        self._sink = sink
        raw = self._raw = stream.extra(SocketAttribute.raw_socket)  # looked up once
        self._send_lock = anyio.Lock()
        task_group.start_soon(self._reader, stream, raw, conn, early, sink)

        def poll() -> None:
            """Read what has already arrived, now, into the reader's connection (the reader
            task would wake for it; it waits on the socket, never inside the decoder). The
            end of the stream or a socket error is left to the reader; a broken stream ends
            the connection here, and the reader, woken, closes the socket."""
            if self._stream is not stream:
                return
            try:
                data = raw.recv(_RECV_SIZE)
            except OSError:
                return
            if not data:
                return
            try:
                events = conn.receive_data(data, received)
                error = deliver(self, events, sink) if events else None
            except FrameError as exc:
                error = exc
            if error is not None:
                self._end(stream, error)

        received = sink.frame_received
        self.poll_now = poll

    async def _open_on_network(
        self, network: MemoryNetwork, sink: FrameSink, task_group: TaskSpawner
    ) -> None:
        """Connect and shake hands over an in-memory network's byte stream; a reader task
        pumps it (:meth:`_read_stream`), :meth:`send` writes each frame."""
        conn = TcpClientConnection(self.node)
        stream: ByteStream | None = None
        try:
            with anyio.fail_after(self.connect_timeout):  # connect and handshake
                stream = await network.connect(self.host, self.port, local_host=self.local_host)
                early = await self._handshake(stream, conn)
        except BaseException as exc:
            if stream is not None:
                with anyio.CancelScope(shield=True):
                    await stream.aclose()
            raise self._open_failed(exc) from exc
        self._mem = stream
        self._send_lock = anyio.Lock()
        task_group.start_soon(self._read_stream, stream, conn, early, sink)

    async def _read_stream(
        self, stream: ByteStream, conn: TcpClientConnection, early: list[TcpEvent], sink: FrameSink
    ) -> None:
        """The pump of a connection over an in-memory network: what the stream gives, into
        the connection, frames out to the sink; a background task ending at a boundary (the
        end of the stream, a broken one, a framing error: the link is lost, reported)."""
        exc: BaseException | None = None
        received = sink.frame_received
        try:
            error = deliver(self, early, sink)
            if error is not None:
                raise error
            while True:
                events = conn.receive_data(await stream.receive(), received)
                if events:
                    error = deliver(self, events, sink)
                    if error is not None:
                        raise error
        except FrameError as err:
            exc = err
        except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError) as err:
            exc = ConnectionLost(f"{self.description} closed the connection")
            exc.__cause__ = err
        except OSError as err:
            exc = wrap_os_error(err, f"connection to {self.description} failed")
        finally:
            conn.close()
            if self._mem is stream:
                self._mem = None
                if exc is not None:
                    sink.connection_lost(exc)
            with anyio.CancelScope(shield=True):
                await stream.aclose()

    async def _send_on_network(
        self, stream: ByteStream, frame: bytes, timeout: float | None
    ) -> None:
        """Write one frame on an in-memory network's stream (its window may make us wait,
        at most ``timeout``)."""
        try:
            with anyio.fail_after(timeout):
                async with self._send_lock:
                    await stream.send(encode_frame(frame))
        except TimeoutError:
            raise FinsTimeout(
                f"cannot send to {self.description} within {timeout} s: the PLC does not "
                "read what was sent"
            ) from None
        except (anyio.BrokenResourceError, anyio.ClosedResourceError) as exc:
            raise ConnectionLost(f"cannot send to {self.description}: {exc!r}") from exc

    def _open_failed(self, exc: BaseException) -> BaseException:
        """What a failed connection attempt raises: a :class:`FinsError` as it is (a refused
        or broken handshake), :class:`ConnectionLost` for a timeout or a socket error."""
        if isinstance(exc, FinsError):
            return exc
        if isinstance(exc, TimeoutError):
            return ConnectionLost(
                f"no FINS/TCP connection or node address reply from {self.description} "
                f"within {self.connect_timeout} s"
            )
        if isinstance(exc, (anyio.EndOfStream, anyio.BrokenResourceError)):
            return ConnectionLost(
                f"{self.description} closed the connection during the FINS/TCP handshake"
            )
        if isinstance(exc, OSError):
            return wrap_os_error(exc, f"cannot connect to {self.description}")
        return exc

    def _end(self, stream: SocketStream, error: BaseException) -> None:
        """End ``stream``'s connection now, from a synchronous path (trio): detach, wake the
        reader (which closes the socket) and report ``error``."""
        if self._stream is stream and self._raw is not None and self._sink is not None:
            raw = self._raw
            self._stream = self._raw = None
            self.poll_now = None
            anyio.notify_closing(raw)
            self._sink.connection_lost(error)

    async def _open_asyncio(self, sink: FrameSink) -> None:
        loop = asyncio.get_running_loop()
        proto = _TcpProtocol(self, sink)
        try:
            with anyio.fail_after(self.connect_timeout):
                sock = await _connect(loop, self.host, self.port)
                try:
                    await loop.create_connection(lambda: proto, sock=sock)
                except BaseException:
                    sock.close()
                    raise
                proto.sock = sock
                assert proto.transport is not None
                proto.transport.write(proto.conn.start())
                self.local_node, self.remote_node = await proto.handshake
        except BaseException as exc:
            handshake = proto.handshake
            if not handshake.done():  # nobody awaits it now: no error for it to keep (and log)
                handshake.cancel()
            elif not handshake.cancelled():
                handshake.exception()  # retrieved: not logged as never retrieved
            if proto.transport is not None:
                proto.transport.close()
            error = self._open_failed(exc)
            if error is exc:
                raise
            raise error from exc
        self._aio = proto
        self.fast_send = proto.send
        self.fast_send_many = proto.send_many
        # A loop that waits for readiness and then reads (selector loops, uvloop) leaves the
        # socket to whoever reads first; a proactor loop (Windows) has a read of its own
        # outstanding at all times, which a read of ours would overtake.
        if isinstance(loop, asyncio.SelectorEventLoop) or is_uvloop(loop):
            self.poll_now = proto.poll

    def _detach(self) -> None:
        self._aio = None
        self.fast_send = None
        self.fast_send_many = None
        self.poll_now = None

    async def _handshake(self, stream: ByteStream, conn: TcpClientConnection) -> list[TcpEvent]:
        """Send our node, read until the server assigned both; returns the events that
        followed the assignment in the same read (the anyio pump of the handshake)."""
        await stream.send(conn.start())
        while True:
            nodes, early = handshake_step(self, conn, await stream.receive())
            if nodes is not None:
                self.local_node, self.remote_node = nodes
                return early

    async def _reader(
        self,
        stream: SocketStream,
        raw: socket.socket,
        conn: TcpClientConnection,
        early: list[TcpEvent],
        sink: FrameSink,
    ) -> None:
        exc: BaseException | None = None
        received = sink.frame_received
        try:
            error = deliver(self, early, sink)
            if error is not None:
                raise error
            # The socket itself, not stream.receive(): that tries a recv() before waiting,
            # which fails once per reply for a request/reply peer (two system calls each).
            while True:
                await anyio.wait_readable(raw)
                if self._stream is not stream:  # ended by the read after a send, which
                    break  # found the stream broken (and read what woke us): close it
                try:
                    data = raw.recv(_RECV_SIZE)
                except (BlockingIOError, InterruptedError):
                    continue
                if not data:
                    raise anyio.EndOfStream
                events = conn.receive_data(data, received)
                if events:
                    error = deliver(self, events, sink)
                    if error is not None:
                        raise error
        except FrameError as err:  # FinsTcpError included: the stream is unusable now
            exc = err
        except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError) as err:
            exc = ConnectionLost(f"{self.description} closed the connection")
            exc.__cause__ = err
        except OSError as err:
            exc = wrap_os_error(err, f"connection to {self.description} failed")
        finally:
            conn.close()
            # Detach and report before closing: closing yields to other tasks, which must
            # not send on the closed socket nor open a new connection while requests of
            # this one are still waiting.
            if self._stream is stream:
                self._stream = self._raw = None
                self.poll_now = None
                if exc is not None:
                    sink.connection_lost(exc)
            with anyio.CancelScope(shield=True):
                await stream.aclose()

    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        if self._aio is not None:
            self._aio.send(frame)  # buffered by the event loop: never waits
            return
        if self._mem is not None:
            await self._send_on_network(self._mem, frame, timeout)
            return
        stream, raw = self._stream, self._raw
        if stream is None or raw is None:
            raise ConnectionLost(f"{self.description} is not connected")
        data = encode_frame(frame)
        sent = 0  # bytes of this message written: once some are, all must be, or none after
        try:
            lock = self._send_lock
            if not lock.locked():  # nobody mid-write: try the socket directly, no await
                try:
                    sent = raw.send(data)
                except (BlockingIOError, InterruptedError):
                    sent = 0
                if sent == len(data):
                    return
            with anyio.move_on_after(timeout) as waited:
                async with lock:  # the rest, in order, behind any other partial write
                    if self._stream is not stream:  # ended while we waited for the lock
                        raise anyio.ClosedResourceError
                    view = memoryview(data)
                    while sent < len(data):
                        await anyio.wait_writable(raw)
                        with contextlib.suppress(BlockingIOError, InterruptedError):
                            sent += raw.send(view[sent:])
        except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError) as exc:
            raise wrap_os_error(exc, f"cannot send to {self.description}") from exc
        except BaseException:
            if 0 < sent < len(data):
                self._end_mid_frame(stream, "its send was cancelled")
            raise
        if waited.cancelled_caught:  # the PLC stopped reading: its window stays full
            if sent:
                self._end_mid_frame(stream, f"not written in whole within {timeout} s")
            raise FinsTimeout(
                f"cannot send to {self.description} within {timeout} s: the PLC does not "
                "read what was sent (its TCP receive window stays full)"
            )

    def _end_mid_frame(self, stream: SocketStream, why: str) -> None:
        """End the connection of a frame left part-written: what followed it on the stream
        would be garbage to the PLC."""
        self._end(
            stream,
            ConnectionLost(
                f"connection to {self.description} ended: a frame was left part-written ({why})"
            ),
        )

    async def aclose(self) -> None:
        proto = self._aio
        self._detach()
        if proto is not None and proto.transport is not None:
            proto.transport.close()
        mem, self._mem = self._mem, None
        if mem is not None:
            with anyio.CancelScope(shield=True):
                await mem.aclose()
        stream, self._stream, self._raw = self._stream, None, None
        if stream is not None:
            self.poll_now = None
            with anyio.CancelScope(shield=True):
                await stream.aclose()
