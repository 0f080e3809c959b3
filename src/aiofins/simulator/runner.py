"""Run one PLC behind several servers at once (UDP, TCP, serial) sharing one fault plan."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Iterator, Sequence
from contextlib import asynccontextmanager, contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING

import anyio

from ..protocol.errors import leaf_errors
from ..protocol.header import FinsAddress
from .ethernet import EthernetUnit
from .faults import Dispatcher, FaultCounters, FaultPlan, FrameHandler
from .serial import SerialServer, SerialSettings
from .tcp import DEFAULT_MAX_CONNECTIONS, DEFAULT_NODE_POOL, MAX_PENDING_HANDSHAKES, TcpServer
from .udp import UdpServer

if TYPE_CHECKING:
    from ..memnet import MemoryNetwork

_logger = logging.getLogger(__name__)


@dataclass(eq=False, slots=True)
class Simulator:
    """The servers of a running simulator (see :func:`run_simulator`)."""

    plc: FrameHandler
    dispatcher: Dispatcher
    udp: UdpServer | None = None
    tcp: TcpServer | None = None
    serial: SerialServer | None = None

    @property
    def plan(self) -> FaultPlan:
        return self.dispatcher.plan

    @property
    def counters(self) -> FaultCounters:
        return self.dispatcher.plan.counters

    @property
    def udp_port(self) -> int:
        if self.udp is None or self.udp.port is None:
            raise RuntimeError("no UDP server is running")
        return self.udp.port

    @property
    def tcp_port(self) -> int:
        if self.tcp is None or self.tcp.port is None:
            raise RuntimeError("no TCP server is running")
        return self.tcp.port

    def urls(self) -> list[str]:
        """Where the simulator listens, as client URLs (``udp://host:port``, ...)."""
        out: list[str] = []
        if self.udp is not None:
            out.append(f"udp://{_host(self.udp.host)}:{self.udp_port}")
        if self.tcp is not None:
            out.append(f"tcp://{_host(self.tcp.host)}:{self.tcp_port}")
        if self.serial is not None:
            options = self.serial.settings.url_options()
            if self.serial.unit:
                options.append(f"unit={self.serial.unit}")
            query = "?" + "&".join(options) if options else ""
            out.append(f"serial://{self.serial.device}{query}")
        return out


@contextmanager
def _naming_the_endpoint(what: str, where: tuple[str, int]) -> Iterator[None]:
    """An OSError from binding (maybe inside a server's task group) says which endpoint:
    ``[Errno 98] Address already in use`` alone does not."""
    try:
        yield
    except Exception as exc:
        leaves = leaf_errors(exc)
        error = leaves[0]
        if len(leaves) != 1 or not isinstance(error, OSError):
            raise
        host, port = where
        raise OSError(
            error.errno, f"cannot serve {what} on {_host(host)}:{port}: {error.strerror or error}"
        ) from exc


def _host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def _plc_node(plc: FrameHandler) -> int:
    address = getattr(plc, "address", None)
    if isinstance(address, FinsAddress) and 1 <= address.node <= 254:
        return address.node
    return 1


@asynccontextmanager
async def run_simulator(
    plc: FrameHandler,
    *,
    udp: tuple[str, int] | None = None,
    tcp: tuple[str, int] | None = None,
    serial: str | None = None,
    faults: FaultPlan | None = None,
    server_node: int | None = None,
    node_pool: Sequence[int] = DEFAULT_NODE_POOL,
    max_connections: int = DEFAULT_MAX_CONNECTIONS,
    max_pending: int = MAX_PENDING_HANDSHAKES,
    handshake_timeout: float | None = None,
    serial_unit: int = 0,
    serial_settings: SerialSettings | None = None,
    network: MemoryNetwork | None = None,
    ethernet: EthernetUnit | None = None,
) -> AsyncIterator[Simulator]:
    """Serve ``plc`` on the given endpoints while the ``async with`` block runs.

    Port 0 binds an ephemeral port (read it from ``sim.udp_port`` / ``sim.tcp_port``). The
    FINS/TCP server node defaults to the PLC's node (``plc.address.node``) or 1;
    ``max_connections``, ``max_pending`` and ``handshake_timeout`` are :class:`TcpServer`'s.
    ``network``: serve UDP and TCP on an in-memory network (:mod:`aiofins.memnet`) instead of
    the operating system's sockets; ``ethernet``: the address conversion of the Ethernet
    Unit the UDP server plays (:class:`~aiofins.simulator.ethernet.EthernetUnit`: where
    replies go; by default to the sender).
    """
    dispatcher = Dispatcher(plc, faults)
    sim = Simulator(plc, dispatcher)
    # The servers are made (their arguments checked) before any task: a bad argument is a
    # ValueError of its own, not one wrapped in an exception group.
    if udp is not None:
        sim.udp = UdpServer(dispatcher, udp[0], udp[1], network=network, ethernet=ethernet)
    if tcp is not None:
        sim.tcp = TcpServer(
            dispatcher,
            tcp[0],
            tcp[1],
            server_node=server_node if server_node is not None else _plc_node(plc),
            node_pool=node_pool,
            max_connections=max_connections,
            max_pending=max_pending,
            handshake_timeout=handshake_timeout,
            network=network,
        )
    if serial is not None:
        sim.serial = SerialServer(dispatcher, serial, unit=serial_unit, settings=serial_settings)
    async with anyio.create_task_group() as tg:
        if udp is not None and sim.udp is not None:
            with _naming_the_endpoint("FINS/UDP", udp):
                await tg.start(sim.udp.serve)
        if tcp is not None and sim.tcp is not None:
            with _naming_the_endpoint("FINS/TCP", tcp):
                await tg.start(sim.tcp.serve)
        if sim.serial is not None:
            await tg.start(sim.serial.serve)
        where = ", ".join(sim.urls())
        _logger.info("virtual PLC serving on %s", where)
        try:
            yield sim
        finally:
            _logger.info("virtual PLC on %s stopped", where)
            tg.cancel_scope.cancel()
