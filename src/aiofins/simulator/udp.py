"""FINS/UDP server: one FINS frame per datagram, answered to the address it came from."""

from __future__ import annotations

import asyncio
import socket
from typing import Any, cast

import anyio
from anyio.abc import TaskGroup, TaskStatus, UDPSocket

from ..protocol.tcp import DEFAULT_PORT
from .faults import Dispatcher


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
        dispatcher = self.server.dispatcher
        if dispatcher.quiet:  # no fault can apply: answer from this callback (the fast case)
            reply = dispatcher.answer_now(data)
            if reply is not None:
                transport.sendto(reply, addr)
            return

        async def send(reply: bytes) -> None:
            transport.sendto(reply, addr)

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
    port, as an Ethernet Unit with dynamic address conversion does.
    """

    def __init__(
        self,
        dispatcher: Dispatcher,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
    ) -> None:
        self.dispatcher = dispatcher
        self.host = host
        self.requested_port = port
        self.port: int | None = None
        self._send_lock = anyio.Lock()

    async def serve(self, *, task_status: TaskStatus[int] = anyio.TASK_STATUS_IGNORED) -> None:
        """Receive and answer datagrams until cancelled."""
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
        self, sock: UDPSocket, tg: TaskGroup, data: bytes, host: str, port: int
    ) -> None:
        async def send(reply: bytes) -> None:
            async with self._send_lock:  # delayed answers are sent from several tasks
                await sock.sendto(reply, host, port)

        await self.dispatcher.dispatch(data, send, peer=f"udp:{host}:{port}", task_group=tg)
