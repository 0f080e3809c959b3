"""FINS/UDP server: one FINS frame per datagram, answered to the address it came from, or
where an Ethernet Unit's FINS address conversion sends it (``ethernet=``, see
:mod:`.ethernet`), on the operating system's sockets or an in-memory network
(``network=``, see :mod:`aiofins.memnet`)."""

from __future__ import annotations

import asyncio
import socket
from typing import TYPE_CHECKING, Any, cast

import anyio
from anyio.abc import TaskGroup, TaskStatus, UDPSocket

from ..protocol.tcp import DEFAULT_PORT
from .ethernet import EthernetUnit
from .faults import Dispatcher

if TYPE_CHECKING:
    from ..memnet import DatagramSocket, MemoryNetwork


def _under_asyncio() -> bool:
    try:
        asyncio.get_running_loop()
    except RuntimeError:  # trio: no asyncio loop running
        return False
    return True


class _FastProtocol(asyncio.DatagramProtocol):
    """asyncio only: answer fault-free requests straight from the event loop's callback."""

    def __init__(self, server: UdpServer, tg: TaskGroup) -> None:
        self.server = server
        self.tg = tg
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: Any) -> None:
        transport = self.transport
        assert transport is not None
        server = self.server
        dispatcher = server.dispatcher
        ethernet = server.ethernet
        if ethernet is not None:  # the unit learns the sender (dynamic conversion)
            ethernet.received(data, (str(addr[0]), int(addr[1])))
        if dispatcher.quiet:  # no fault can apply: answer from this callback (the fast case)
            reply = dispatcher.answer_now(data)
            if reply is not None:
                to = addr if ethernet is None else ethernet.destination(reply)
                if to is not None:
                    transport.sendto(reply, to)
            return

        async def send(reply: bytes) -> None:
            to = addr if ethernet is None else ethernet.destination(reply)
            if to is not None:
                transport.sendto(reply, to)

        peer = f"udp:{addr[0]}:{addr[1]}"
        self.tg.start_soon(self._dispatch, data, send, peer)

    async def _dispatch(self, data: bytes, send: Any, peer: str) -> None:
        await self.server.dispatcher.dispatch(data, send, peer=peer, task_group=self.tg)

    def error_received(self, exc: Exception) -> None:
        pass  # e.g. ICMP port unreachable from a client that went away


class UdpServer:
    """Serve a :class:`~aiofins.simulator.faults.Dispatcher` on a UDP port.

    Port 0 binds an ephemeral port; :attr:`port` holds the bound port once serving (and
    ``task_group.start(server.serve)`` returns it). Replies go to the sender's address and
    port, as an Ethernet Unit with dynamic address conversion does; with ``ethernet`` (an
    :class:`~aiofins.simulator.ethernet.EthernetUnit`) where that unit's address conversion
    sends them (a unit with static conversion or an IP address table replies to the FINS
    port of the address it derives or looks up: a client on another port gets nothing).
    ``network``: serve on an in-memory network instead of the operating system's sockets.
    """

    def __init__(
        self,
        dispatcher: Dispatcher,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        *,
        network: MemoryNetwork | None = None,
        ethernet: EthernetUnit | None = None,
    ) -> None:
        self.dispatcher = dispatcher
        self.network = network
        self.ethernet = ethernet
        self.host = host
        self.requested_port = port
        self.port: int | None = None
        self._send_lock = anyio.Lock()

    async def serve(self, *, task_status: TaskStatus[int] = anyio.TASK_STATUS_IGNORED) -> None:
        """Receive and answer datagrams until cancelled."""
        if self.network is not None:
            await self._serve_network(self.network, task_status)
            return
        if _under_asyncio():
            await self._serve_asyncio(task_status)
            return
        sock = await anyio.create_udp_socket(local_host=self.host, local_port=self.requested_port)
        async with sock, anyio.create_task_group() as tg:
            self.port = int(sock.extra(anyio.abc.SocketAttribute.local_port))
            task_status.started(self.port)
            while True:
                try:
                    data, address = await sock.receive()
                except OSError:
                    continue  # e.g. an ICMP port-unreachable surfaced on the socket
                # IPv6 addresses come with flow info and scope id: keep host and port
                await self._handle(sock, tg, data, str(address[0]), int(address[1]))

    async def _serve_network(self, network: MemoryNetwork, task_status: TaskStatus[int]) -> None:
        sock = network.datagram_socket(self.host, self.requested_port)
        try:
            async with anyio.create_task_group() as tg:
                self.port = sock.local_address[1]
                task_status.started(self.port)
                while True:
                    try:
                        data, (host, port) = await sock.receive()
                    except OSError:
                        continue
                    await self._handle(sock, tg, data, host, port)
        finally:
            sock.close()

    async def _serve_asyncio(self, task_status: TaskStatus[int]) -> None:
        loop = asyncio.get_running_loop()
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        async with anyio.create_task_group() as tg:
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _FastProtocol(self, tg),
                local_addr=(self.host, self.requested_port),
                family=family,
            )
            try:
                self.port = int(transport.get_extra_info("sockname")[1])
                task_status.started(self.port)
                await anyio.sleep_forever()
            finally:
                transport.close()

    async def _handle(
        self, sock: UDPSocket | DatagramSocket, tg: TaskGroup, data: bytes, host: str, port: int
    ) -> None:
        ethernet = self.ethernet
        if ethernet is not None:  # the unit learns the sender (dynamic conversion)
            ethernet.received(data, (host, port))

        async def send(reply: bytes) -> None:
            # Where the reply goes is decided as it is sent (a later command may have
            # taught a dynamic table another port for the node meanwhile).
            to = (host, port) if ethernet is None else ethernet.destination(reply)
            if to is None:
                return
            async with self._send_lock:  # delayed answers are sent from several tasks
                if isinstance(sock, UDPSocket):
                    await sock.sendto(reply, *to)
                else:
                    sock.sendto(reply, to)

        await self.dispatcher.dispatch(data, send, peer=f"udp:{host}:{port}", task_group=tg)
