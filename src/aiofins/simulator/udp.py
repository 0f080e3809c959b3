"""FINS/UDP server: one FINS frame per datagram, answered to the address it came from."""

from __future__ import annotations

import anyio
from anyio.abc import TaskGroup, TaskStatus, UDPSocket

from ..protocol.tcp import DEFAULT_PORT
from .faults import Dispatcher


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

    async def _handle(
        self, sock: UDPSocket, tg: TaskGroup, data: bytes, host: str, port: int
    ) -> None:
        async def send(reply: bytes) -> None:
            async with self._send_lock:  # delayed answers are sent from several tasks
                await sock.sendto(reply, host, port)

        await self.dispatcher.dispatch(data, send, peer=f"udp:{host}:{port}", task_group=tg)
