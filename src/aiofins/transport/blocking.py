"""UDP and FINS/TCP on a plain blocking socket, for a caller without an event loop.

The blocking client (:mod:`aiofins.sync`) drives a session from the calling thread: it sends
with :attr:`~BlockingTransport.fast_send` and then waits in :meth:`BlockingTransport.receive`
for at most the time its session's clock says is left, which hands every frame that arrives
to the session (the sink) as the event-loop transports do. Nothing runs in the background:
a frame is read only while a caller waits in :meth:`~BlockingTransport.receive`.

The wait is the kernel's: the socket stays in blocking mode and its receive timeout
(``SO_RCVTIMEO``) bounds each ``recv()``, set only when the time left is shorter than the
one in place, or much longer (a ``recv()`` that returns early costs one more call; one that
returns late would not). A ``recv()`` on a blocking socket is one system call, where a
Python socket timeout polls first. (Windows, which takes ``SO_RCVTIMEO`` in another form,
uses the Python socket timeout.)

:meth:`~BlockingTransport.interrupt` may be called from another thread: it shuts the socket
down, which ends a ``recv()`` waiting in the caller's thread at once (the caller then finds
its client closing), and every later one.

The socket code itself is shared with the event-loop transports: the UDP socket is made by
:func:`aiofins.transport.udp.udp_socket`, the FINS/TCP handshake and framing are
:class:`~aiofins.protocol.tcp.TcpClientConnection`'s, the events after them go to the sink
through :func:`aiofins.transport.tcp.deliver`.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import sys
from collections.abc import Callable

from ..protocol.errors import ConnectionLost, FinsError, FinsTimeout, FrameError
from ..protocol.tcp import DEFAULT_PORT as TCP_PORT
from ..protocol.tcp import (
    MAX_NODE,
    TcpClientConnection,
    TcpConnectionState,
    TcpEvent,
    encode_frame,
)
from .base import FrameSink, TaskSpawner, Transport, url_host, wrap_os_error
from .tcp import DEFAULT_CONNECT_TIMEOUT, deliver, handshake_step
from .udp import DEFAULT_PORT as UDP_PORT
from .udp import DEFAULT_RCVBUF, udp_socket

#: Bytes asked of one ``recv()`` of a datagram: above the largest FINS frame.
_DATAGRAM_SIZE = 4096
#: Bytes asked of one ``recv()`` of the FINS/TCP stream: a few replies of the largest frame.
_STREAM_SIZE = 65536
#: The shortest receive timeout set (a zero ``SO_RCVTIMEO`` would mean "wait for ever").
_MIN_WAIT = 1e-6
#: A receive timeout in place is set again when the time left is this many times longer.
_LONGER = 4.0
#: Whether the kernel's receive timeout is used (else the Python socket timeout).
_KERNEL_TIMEOUT = sys.platform != "win32" and hasattr(socket, "SO_RCVTIMEO")


class BlockingTransport(Transport):
    """The part of the blocking transports they share: the socket, its receive timeout,
    :meth:`receive`, :meth:`interrupt` and :meth:`close`. Made closed; :meth:`connect`
    opens it (the event-loop form :meth:`open` does the same, blocking)."""

    reconnectable = True

    def __init__(self) -> None:
        self._sock: socket.socket | None = None
        self._sink: FrameSink | None = None
        self._recv: Callable[[int], bytes] | None = None
        #: The receive timeout in place (seconds; 0: none set yet).
        self._wait = 0.0
        #: :meth:`interrupt` was called: the socket is shut down.
        self._interrupted = False

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    def connect(self, sink: FrameSink, timeout: float) -> None:
        """Open the link within ``timeout`` seconds (blocking); frames go to ``sink``.
        Raises :class:`ConnectionLost` (or a FINS/TCP error) when it cannot."""
        raise NotImplementedError

    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        if not self.is_open:
            self.connect(sink, DEFAULT_CONNECT_TIMEOUT)

    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        send = self.fast_send
        if send is None:
            raise ConnectionLost(f"{self.description} is closed")
        send(frame)

    async def aclose(self) -> None:
        self.close()

    def _attach(self, sock: socket.socket, sink: FrameSink) -> None:
        """``sock`` (connected) is the link now, in blocking mode."""
        sock.settimeout(None)
        self._sock = sock
        self._sink = sink
        self._recv = sock.recv
        self._wait = 0.0
        self._interrupted = False

    def _set_wait(self, sock: socket.socket, wait: float) -> None:
        """Bound the next ``recv()`` by half of ``wait`` seconds: the next call's time left,
        a little shorter or longer, then needs no new setting (see the module)."""
        wait *= 0.5
        if wait < _MIN_WAIT:
            wait = _MIN_WAIT
        self._wait = wait
        if _KERNEL_TIMEOUT:
            whole = int(wait)
            sock.setsockopt(
                socket.SOL_SOCKET,
                socket.SO_RCVTIMEO,
                struct.pack("ll", whole, max(int((wait - whole) * 1e6), 1)),
            )
        else:  # pragma: no cover - Windows
            sock.settimeout(wait)

    def _read(self, wait: float, size: int) -> bytes | None:
        """One ``recv()`` of at most ``size`` bytes within ``wait`` seconds: the bytes, or
        ``None`` when none came in time (or it returned early). ``b""`` is the end of a
        stream. Raises :class:`ConnectionLost` once interrupted or on a socket error."""
        sock = self._sock
        recv = self._recv
        if sock is None or recv is None:
            raise ConnectionLost(f"{self.description} is closed")
        held = self._wait
        if wait < held or wait > _LONGER * held:
            self._set_wait(sock, wait)
        try:
            data = recv(size)
        except (BlockingIOError, InterruptedError, TimeoutError):
            return None
        except OSError as exc:
            if isinstance(exc, ConnectionRefusedError) and not self._interrupted:
                # ICMP port unreachable (UDP): counted, not fatal; the request times out.
                if self._sink is not None:
                    self._sink.frame_dropped(f"socket error: {exc}")
                return None
            raise self._failure(exc) from exc
        if self._interrupted:
            raise self._failure(None)
        return data

    def _failure(self, exc: BaseException | None, doing: str = "") -> FinsError:
        """The error a caller gets from a socket that failed (or was interrupted) while
        ``doing`` (default: receiving)."""
        if self._interrupted or exc is None:
            return ConnectionLost(f"{self.description} was closed")
        return wrap_os_error(exc, doing or self.description)

    def _lost(self, error: FinsError) -> None:
        """The link ended with ``error``: the socket closed and the sink told (not after
        :meth:`interrupt`: the owner is closing it)."""
        sink = self._sink
        interrupted = self._interrupted
        self.close()
        if sink is not None and not interrupted:
            sink.connection_lost(error)

    def receive(self, wait: float) -> None:
        """Wait at most ``wait`` seconds for what the peer sends and hand every whole frame
        to the sink (nothing when the time passes; it may also return early, having read
        nothing or a frame for no one). Raises :class:`ConnectionLost` (and closes) when
        the link ended."""
        raise NotImplementedError

    def interrupt(self) -> None:
        """End a :meth:`receive` waiting in another thread, and every later one, with
        :class:`ConnectionLost` (thread-safe; the socket is closed by :meth:`close`)."""
        sock = self._sock
        if sock is None or self._interrupted:
            return
        self._interrupted = True
        with contextlib.suppress(OSError):  # not connected (any more): nothing waits
            sock.shutdown(socket.SHUT_RDWR)

    def close(self) -> None:
        """Close the socket (idempotent)."""
        sock, self._sock = self._sock, None
        self._recv = None
        self.fast_send = None
        if sock is not None:
            sock.close()


class BlockingUdpTransport(BlockingTransport):
    """FINS/UDP to ``host:port`` on a blocking socket (see the module): one datagram is
    one frame; the socket is the event-loop :class:`~aiofins.transport.UdpTransport`'s."""

    own_source_node = True

    def __init__(
        self,
        host: str,
        port: int = UDP_PORT,
        *,
        local_host: str | None = None,
        local_port: int = 0,
        rcvbuf: int = DEFAULT_RCVBUF,
    ) -> None:
        super().__init__()
        self.host = host
        self.port = port
        self.local_host = local_host
        self.local_port = local_port
        self.rcvbuf = rcvbuf

    @property
    def description(self) -> str:
        return f"udp://{url_host(self.host)}:{self.port}"

    def connect(self, sink: FrameSink, timeout: float) -> None:
        if self.is_open:
            return
        try:
            infos = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)
            family, _, _, _, remote = infos[0]
            sock = udp_socket(family, remote, self.local_host, self.local_port, self.rcvbuf)
        except OSError as exc:
            raise wrap_os_error(exc, f"cannot open {self.description}") from exc
        self._attach(sock, sink)
        raw_send = sock.send
        description = self.description

        def send(frame: bytes) -> None:
            try:
                raw_send(frame)
            except ConnectionRefusedError as exc:  # an earlier ICMP error surfacing here
                sink.frame_dropped(f"socket error: {exc}")
            except OSError as exc:
                raise self._failure(exc, f"cannot send to {description}") from exc

        self.fast_send = send

    def receive(self, wait: float) -> None:
        # (_read() inlined: once per request)
        sock = self._sock
        if sock is None:
            raise ConnectionLost(f"{self.description} is closed")
        held = self._wait
        if wait < held or wait > _LONGER * held:
            self._set_wait(sock, wait)
        try:
            data = sock.recv(_DATAGRAM_SIZE)
        except (BlockingIOError, InterruptedError, TimeoutError):
            return
        except OSError as exc:
            if isinstance(exc, ConnectionRefusedError) and not self._interrupted:
                # ICMP port unreachable: counted, not fatal; the request times out.
                if self._sink is not None:
                    self._sink.frame_dropped(f"socket error: {exc}")
                return
            error = self._failure(exc)
            self._lost(error)
            raise error from exc
        if self._interrupted:
            raise self._failure(None)
        if self._sink is not None:
            self._sink.frame_received(data)


class BlockingTcpTransport(BlockingTransport):
    """FINS/TCP to ``host:port`` on a blocking socket (see the module); ``node`` 0 lets the
    PLC allocate our node. The handshake and the framing are
    :class:`~aiofins.protocol.tcp.TcpClientConnection`'s, as for
    :class:`~aiofins.transport.TcpTransport`. A frame that cannot be written within
    ``connect_timeout`` (a peer that stopped reading) ends the connection."""

    fresh_sid_space = True
    reliable = True

    def __init__(
        self,
        host: str,
        port: int = TCP_PORT,
        *,
        node: int = 0,
        connect_timeout: float = DEFAULT_CONNECT_TIMEOUT,
    ) -> None:
        if not 0 <= node <= MAX_NODE:
            raise FrameError(f"FINS/TCP client node {node} out of range 0..{MAX_NODE}")
        super().__init__()
        self.host = host
        self.port = port
        self.node = node
        self.connect_timeout = connect_timeout
        self._conn: TcpClientConnection | None = None
        self.local_node: int | None = None
        self.remote_node: int | None = None

    @property
    def description(self) -> str:
        return f"tcp://{url_host(self.host)}:{self.port}"

    def connect(self, sink: FrameSink, timeout: float) -> None:
        if self.is_open:
            return
        timeout = min(timeout, self.connect_timeout)
        try:
            sock = socket.create_connection((self.host, self.port), timeout=timeout)
        except OSError as exc:
            if isinstance(exc, TimeoutError):
                raise FinsTimeout(
                    f"no connection to {self.description} within {timeout:.3g} s"
                ) from exc
            raise wrap_os_error(exc, f"cannot connect to {self.description}") from exc
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn = TcpClientConnection(self.node)
            sock.sendall(conn.start())
            early = self._handshake(sock, conn)
        except BaseException as exc:
            sock.close()
            if isinstance(exc, TimeoutError):
                raise FinsTimeout(
                    f"{self.description} did not complete the FINS/TCP handshake within "
                    f"{timeout:.3g} s"
                ) from exc
            if isinstance(exc, OSError):
                raise wrap_os_error(exc, f"cannot connect to {self.description}") from exc
            raise
        self._conn = conn
        self._attach(sock, sink)
        if _KERNEL_TIMEOUT:  # a write that cannot go out within the connect timeout fails
            whole = int(timeout)
            sock.setsockopt(
                socket.SOL_SOCKET,
                socket.SO_SNDTIMEO,
                struct.pack("ll", whole, max(int((timeout - whole) * 1e6), 1)),
            )
        sendall = sock.sendall
        description = self.description

        def send(frame: bytes) -> None:
            try:
                sendall(encode_frame(frame))
            except OSError as exc:
                error = self._failure(exc, f"cannot send to {description}")
                self._lost(error)  # part of a frame may have gone out: the stream is unusable
                raise error from exc

        self.fast_send = send
        error = deliver(self, early, sink)
        if error is not None:
            self.close()
            raise error

    def _handshake(self, sock: socket.socket, conn: TcpClientConnection) -> list[TcpEvent]:
        """Read until the node address reply; the events that followed it."""
        while True:
            data = sock.recv(_STREAM_SIZE)  # bounded by the connect's socket timeout
            if not data:
                raise ConnectionLost(
                    f"{self.description} closed the connection during the FINS/TCP handshake"
                )
            nodes, early = handshake_step(self, conn, data)
            if nodes is not None:
                self.local_node, self.remote_node = nodes
                return list(early)

    def receive(self, wait: float) -> None:
        try:
            data = self._read(wait, _STREAM_SIZE)
        except FinsError as exc:  # a socket error (a reset), or closed by interrupt()
            self._lost(exc)
            raise
        if data is None:
            return
        sink, conn = self._sink, self._conn
        assert sink is not None and conn is not None
        if not data:
            error: FinsError | None = ConnectionLost(f"{self.description} closed the connection")
        else:
            try:
                events = conn.receive_data(data, sink.frame_received)
                error = deliver(self, events, sink) if events else None
            except FrameError as exc:
                error = exc
        if error is not None:
            self._lost(error)
            raise error

    def close(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None and conn.state is not TcpConnectionState.CLOSED:
            conn.close()
        super().close()
