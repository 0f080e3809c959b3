"""FINS/TCP server (W421 §7): handshake with node allocation, then FINS frames in command 2.

Handshake: the client sends command 0 with its FINS node (0 = allocate one); the server answers
command 1 with the client node and its own node, or with an error code and closes:

* ``0x20`` all connections in use (``max_connections`` connections have completed the
  handshake),
* ``0x21`` the fixed node asked for is held by another connection,
* ``0x23`` the node asked for is out of range 1..254,
* ``0x24`` the node asked for is the server's own node,
* ``0x25`` no node left in the allocation pool (default 239..254, as on a CS1W-ETN21),
* a :class:`~aiofins.simulator.faults.FaultPlan`'s ``tcp_refusal`` code for every handshake.

A bad header (1), an impossible length (2) or a command other than 2 after the handshake (3)
gets command 3 with that error code, and the connection closes. SA1 of every FINS frame is
set to the connection's node so that the response's DA1 names it.

Only connections that completed the handshake count against ``max_connections``. The others
(accepted, no node yet) are held to a small separate cap, ``max_pending``, and a short
deadline, ``handshake_timeout``: when one more arrives over the cap, the oldest of them is
closed (a real client sends its handshake at once; idle sockets cannot lock it out).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING

import anyio
from anyio.abc import ByteStream, SocketAttribute, SocketListener, TaskGroup, TaskStatus

from ..protocol.errors import FinsTcpError
from ..protocol.tcp import (
    DEFAULT_PORT,
    TcpCommand,
    TcpDecoder,
    TcpErrorCode,
    TcpMessage,
    encode_error_notification,
    encode_frame,
    encode_message,
    encode_node_response,
    parse_node_request,
)
from .faults import Dispatcher

if TYPE_CHECKING:
    from ..memnet import MemoryNetwork, StreamListener

#: Client nodes a CS1W-ETN21 allocates automatically (W421: 239-254).
DEFAULT_NODE_POOL = tuple(range(239, 255))
#: FINS/TCP connections per Ethernet Unit (W421).
DEFAULT_MAX_CONNECTIONS = 16
#: A connection that has not completed the FINS/TCP handshake by then (seconds) is closed.
HANDSHAKE_TIMEOUT = 2.0
#: Connections accepted but not yet through the handshake; over this, the oldest is closed.
MAX_PENDING_HANDSHAKES = 8
_SA1 = 7
_logger = logging.getLogger(__name__)


def _whole(value: object) -> bool:
    """An ``int`` (not a ``bool``, a float or NaN, which compare false with every bound)."""
    return isinstance(value, int) and not isinstance(value, bool)


class ConnectionState(Enum):
    """Where one accepted FINS/TCP connection is (:meth:`TcpServer._enter` moves it)."""

    #: Accepted, no handshake yet: counts against ``max_pending``; ``handshake_timeout`` runs.
    PENDING = "pending"
    #: Through the handshake, holding its client node: counts against ``max_connections``.
    CONNECTED = "connected"
    #: Closed (by the peer, a refusal, a protocol error, the deadline or an eviction); its
    #: node, if it had one, is free again.
    CLOSED = "closed"


@dataclass(eq=False, slots=True)
class _Connection:
    stream: ByteStream
    host: str
    port: int
    lock: anyio.Lock = field(default_factory=anyio.Lock)
    node: int | None = None
    state: ConnectionState = ConnectionState.PENDING
    #: Cancelled to close the connection (handshake deadline, eviction, end of its run).
    scope: anyio.CancelScope = field(default_factory=anyio.CancelScope)

    async def send(self, data: bytes) -> None:
        async with self.lock:
            await self.stream.send(data)


class TcpServer:
    """Serve a :class:`~aiofins.simulator.faults.Dispatcher` over FINS/TCP."""

    def __init__(
        self,
        dispatcher: Dispatcher,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        *,
        server_node: int = 1,
        node_pool: Sequence[int] = DEFAULT_NODE_POOL,
        max_connections: int = DEFAULT_MAX_CONNECTIONS,
        max_pending: int = MAX_PENDING_HANDSHAKES,
        handshake_timeout: float | None = None,
        network: MemoryNetwork | None = None,
    ) -> None:
        if not _whole(server_node) or not 1 <= server_node <= 254:
            raise ValueError(
                f"FINS/TCP server node must be a whole number, 1..254; got {server_node!r}"
            )
        for number in node_pool:
            if not _whole(number) or not 1 <= number <= 254:
                raise ValueError(f"FINS/TCP node pool: node {number!r} out of range 1..254")
        for name, value in (("max_connections", max_connections), ("max_pending", max_pending)):
            if not _whole(value) or value < 1:
                raise ValueError(f"{name} must be a whole number, at least 1; got {value!r}")
        if handshake_timeout is None:
            handshake_timeout = HANDSHAKE_TIMEOUT
        if not 0 < handshake_timeout < float("inf"):
            raise ValueError(f"handshake_timeout {handshake_timeout} must be a positive number")
        self.dispatcher = dispatcher
        #: Serve on this in-memory network instead of the operating system's sockets.
        self.network = network
        self.host = host
        self.requested_port = port
        self.port: int | None = None
        self.server_node = server_node
        self.node_pool = tuple(n for n in node_pool if n != server_node)
        self.max_connections = max_connections
        self.max_pending = max_pending
        self.handshake_timeout = handshake_timeout
        #: FINS frames whose SA1 was not the connection's node (rewritten).
        self.source_node_rewrites = 0
        #: accept() failures (e.g. no file descriptors left): the listener goes on.
        self.accept_errors = 0
        #: Connections closed for not completing the handshake within ``handshake_timeout``.
        self.handshake_timeouts = 0
        #: Connections without a handshake closed to make room for a newer one (max_pending).
        self.pending_evictions = 0
        #: Error notifications sent (command 3: bad magic or length, unexpected command).
        self.error_notifications = 0
        #: Handshakes refused (node in use, none free, out of range, all connections in use...).
        self.handshake_refusals = 0
        #: Accepted, no handshake yet; oldest first (a dict keeps insertion order).
        self._pending: dict[_Connection, None] = {}
        self._nodes: dict[int, _Connection] = {}

    @property
    def connected_nodes(self) -> list[int]:
        """Client nodes of the connections that completed the handshake."""
        return sorted(self._nodes)

    async def serve(self, *, task_status: TaskStatus[int] = anyio.TASK_STATUS_IGNORED) -> None:
        """Accept connections until cancelled."""
        if self.network is not None:
            mem = self.network.listen(self.host, self.requested_port)
            try:
                async with anyio.create_task_group() as tg:
                    self.port = mem.port
                    task_status.started(self.port)
                    await self._accept(mem, tg)
            finally:
                mem.close()
            return
        listener = await anyio.create_tcp_listener(
            local_host=self.host, local_port=self.requested_port
        )
        async with listener, anyio.create_task_group() as tg:
            self.port = int(listener.extra(SocketAttribute.local_port))
            task_status.started(self.port)
            for one in listener.listeners:  # one per address family of the host
                assert isinstance(one, SocketListener)
                tg.start_soon(self._accept, one, tg)

    async def _accept(self, listener: SocketListener | StreamListener, tg: TaskGroup) -> None:
        while True:
            try:
                stream = await listener.accept()
            except anyio.ClosedResourceError:
                return
            except (OSError, anyio.BrokenResourceError) as exc:
                # e.g. EMFILE: one failed accept must not take the simulator down
                self.accept_errors += 1
                _logger.warning("FINS/TCP accept failed: %s", exc)
                await anyio.sleep(0.05)
                continue
            tg.start_soon(self._connection, self._admit(stream))

    def _admit(self, stream: ByteStream) -> _Connection:
        """A new connection, pending its handshake; the oldest pending one is closed if
        there are already ``max_pending``."""
        address = stream.extra(SocketAttribute.remote_address)
        host, port = (str(address[0]), int(address[1])) if isinstance(address, tuple) else ("", 0)
        conn = _Connection(stream, host, port)
        while len(self._pending) >= self.max_pending:
            oldest = next(iter(self._pending))
            self._enter(oldest, ConnectionState.CLOSED)
            oldest.scope.cancel()
            self.pending_evictions += 1
        self._pending[conn] = None
        return conn

    def _enter(self, conn: _Connection, state: ConnectionState, node: int | None = None) -> None:
        """The one place a connection changes state, and the pending and node tables with it."""
        self._pending.pop(conn, None)
        if state is ConnectionState.CONNECTED:
            assert node is not None and conn.state is ConnectionState.PENDING
            conn.node = node
            self._nodes[node] = conn
            _logger.info(
                "FINS/TCP client %s:%s connected as node %d",
                conn.host,
                conn.port,
                node,
                extra={"node": node},
            )
        elif (
            state is ConnectionState.CLOSED
            and conn.node is not None
            and self._nodes.get(conn.node) is conn
        ):
            del self._nodes[conn.node]
            _logger.info(
                "FINS/TCP client %s:%s (node %d) disconnected",
                conn.host,
                conn.port,
                conn.node,
                extra={"node": conn.node},
            )
        conn.state = state

    async def _connection(self, conn: _Connection) -> None:
        try:
            with conn.scope:
                async with conn.stream, anyio.create_task_group() as tg:
                    tg.start_soon(self._handshake_deadline, conn)
                    await self._run(conn, tg)
                    conn.scope.cancel()
        except Exception:
            # one connection's failure must not stop the listener and the other connections
            _logger.exception("FINS/TCP connection from %s:%s failed", conn.host, conn.port)
        finally:
            self._enter(conn, ConnectionState.CLOSED)

    async def _notify_error(self, conn: _Connection, code: int) -> None:
        self.error_notifications += 1
        await conn.send(encode_error_notification(code))

    async def _handshake_deadline(self, conn: _Connection) -> None:
        """Close a connection that holds a descriptor without ever completing the handshake."""
        await anyio.sleep(self.handshake_timeout)
        if conn.state is ConnectionState.PENDING:
            self.handshake_timeouts += 1
            conn.scope.cancel()

    async def _run(self, conn: _Connection, tg: TaskGroup) -> None:
        """Read messages until the peer closes or breaks the protocol."""
        decoder = TcpDecoder()
        try:
            async for chunk in conn.stream:
                try:
                    messages = decoder.feed(chunk)
                except FinsTcpError as exc:
                    await self._notify_error(conn, exc.tcp_error_code)
                    return
                for message in messages:
                    if not await self._message(conn, message, tg):
                        return
        except (anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
            return

    async def _message(self, conn: _Connection, message: TcpMessage, tg: TaskGroup) -> bool:
        """Handle one message; ``False`` closes the connection."""
        if conn.state is ConnectionState.PENDING:
            if message.command != TcpCommand.NODE_ADDRESS_REQUEST or len(message.payload) != 4:
                await self._notify_error(conn, TcpErrorCode.COMMAND_NOT_SUPPORTED)
                return False
            return await self._handshake(conn, parse_node_request(message))
        if conn.node is None:  # CLOSED (evicted): its scope is cancelled already
            return False
        if message.command != TcpCommand.FRAME:
            await self._notify_error(conn, TcpErrorCode.COMMAND_NOT_SUPPORTED)
            return False
        frame = message.payload
        if len(frame) > _SA1 and frame[_SA1] != conn.node:
            self.source_node_rewrites += 1
            frame = frame[:_SA1] + bytes((conn.node,)) + frame[_SA1 + 1 :]

        async def send(reply: bytes) -> None:
            await conn.send(encode_frame(reply))

        await self.dispatcher.dispatch(
            frame, send, peer=f"tcp:{conn.host}:{conn.port}:{conn.node}", task_group=tg
        )
        return True

    async def _handshake(self, conn: _Connection, requested: int) -> bool:
        plan = self.dispatcher.plan
        error = TcpErrorCode.NORMAL.value
        node = requested
        if plan.tcp_refusal is not None:
            error = plan.tcp_refusal
            plan.counters.tcp_refusals += 1
        elif len(self._nodes) >= self.max_connections:
            error = TcpErrorCode.ALL_CONNECTIONS_IN_USE
        elif requested == 0:
            free = [n for n in self.node_pool if n not in self._nodes]
            if free:
                node = free[0]
            else:
                error = TcpErrorCode.NO_NODE_AVAILABLE
        elif requested > 254:
            error = TcpErrorCode.CLIENT_NODE_OUT_OF_RANGE
        elif requested == self.server_node:
            error = TcpErrorCode.SAME_NODE_ADDRESS
        elif requested in self._nodes:
            error = TcpErrorCode.NODE_ALREADY_CONNECTED
            holder = self._nodes[requested]
            if holder.host == conn.host:
                # W421: a second request from the same IP and node: confirm the old connection.
                with contextlib.suppress(
                    anyio.BrokenResourceError, anyio.ClosedResourceError, OSError
                ):
                    await holder.send(encode_message(TcpCommand.CONNECTION_CONFIRMATION))
        if not error:  # taken before the answer goes out: no other handshake may take it
            self._enter(conn, ConnectionState.CONNECTED, node)
        await conn.send(encode_node_response(node, self.server_node, error))
        if error:
            self.handshake_refusals += 1
            _logger.info(
                "FINS/TCP handshake from %s:%s refused with error %#x",
                conn.host,
                conn.port,
                error,
                extra={"node": requested},
            )
            return False
        return True
