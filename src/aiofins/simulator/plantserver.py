"""Serve a :class:`~aiofins.simulator.plant.Plant` on UDP: one socket per Ethernet unit."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
from anyio.abc import UDPSocket

from .plant import Plant, Unit

_logger = logging.getLogger("aiofins.simulator")


class PlantServer:
    """The UDP sockets of a plant's Ethernet units (those with a ``host``), bound while
    :func:`serve_plant` runs. :attr:`ports` maps each unit (by ``id``) to its bound port."""

    def __init__(self, plant: Plant) -> None:
        self.plant = plant
        self.units = [u for s in plant.stations for u in s.units if u.host is not None]
        self._sockets: dict[int, UDPSocket] = {}
        self.ports: dict[int, int] = {}
        #: Datagrams a socket could not send (e.g. no route to a table's address).
        self.send_errors = 0

    def port_of(self, unit: Unit) -> int:
        return self.ports[id(unit)]

    async def _serve_unit(self, unit: Unit, sock: UDPSocket) -> None:
        while True:
            try:
                data, address = await sock.receive()
            except OSError:
                continue  # an ICMP error surfaced on the socket
            try:
                sends = self.plant.receive(unit, data, str(address[0]), int(address[1]))
            except Exception:  # a bug, not the peer's doing: counted and logged, served on
                self.plant.counts["dropped:internal-error"] += 1
                _logger.exception("plant: a datagram from %s could not be routed", address)
                continue
            for out in sends:
                try:
                    await self._sockets[id(out.unit)].sendto(out.frame, out.host, out.port)
                except OSError as exc:
                    self.send_errors += 1
                    _logger.debug("plant: cannot send to %s:%s: %s", out.host, out.port, exc)


@asynccontextmanager
async def serve_plant(plant: Plant) -> AsyncIterator[PlantServer]:
    """Bind every Ethernet unit's socket (port 0: an ephemeral port) and route until the
    ``async with`` block ends."""
    server = PlantServer(plant)
    try:
        for unit in server.units:
            assert unit.host is not None
            sock = await anyio.create_udp_socket(local_host=unit.host, local_port=unit.port)
            server._sockets[id(unit)] = sock
            server.ports[id(unit)] = int(sock.extra(anyio.abc.SocketAttribute.local_port))
        async with anyio.create_task_group() as tg:
            for unit in server.units:
                tg.start_soon(server._serve_unit, unit, server._sockets[id(unit)])
            try:
                yield server
            finally:
                tg.cancel_scope.cancel()
    finally:
        for sock in server._sockets.values():
            await sock.aclose()
