"""The real UdpTransport and TcpTransport over the in-memory network (``network=``), against
the simulator's real servers on the same network: values asserted, under asyncio, uvloop and
trio; timing exactly under trio's MockClock."""

from __future__ import annotations

from collections.abc import Sequence

import anyio
import pytest

from aiofins.memnet import MemoryNetwork, Packet
from aiofins.protocol.errors import ConnectionLost, FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.transport import TcpTransport, UdpTransport

from ..virtual_time import VIRTUAL_BACKENDS, run_on_virtual_time

PLC_IP, OUR_IP = "192.168.250.10", "192.168.250.2"
READ_D0_2 = bytes.fromhex("820000000002")  # DM 0, two words


def make_plc() -> VirtualPLC:
    plc = VirtualPLC(node=10)
    plc.memory.write_words(0x82, 0, [0xBEEF, 0x0102])
    return plc


def session(transport: UdpTransport | TcpTransport, **options: object) -> Session:
    return Session(transport, source=FinsAddress(0, 2, 0), dest=FinsAddress(0, 10, 0), **options)  # type: ignore[arg-type]


@pytest.mark.anyio
async def test_udp_and_fins_tcp_read_from_the_simulator_over_the_network(
    anyio_backend: object,
) -> None:
    async with (
        MemoryNetwork() as net,
        run_simulator(make_plc(), udp=(PLC_IP, 9600), tcp=(PLC_IP, 9600), network=net) as sim,
    ):
        assert (sim.udp_port, sim.tcp_port) == (9600, 9600)
        udp = UdpTransport(PLC_IP, local_host=OUR_IP, network=net)
        async with session(udp) as s:
            r = await s.request(0x01, 0x01, READ_D0_2, idempotent=True)
            assert r.data == bytes.fromhex("BEEF0102")
            assert udp.local_address == (OUR_IP, 49152)
            assert udp.peer_link == f"udp://{PLC_IP}:9600"
            assert s.sid_spaces == 1
        tcp = TcpTransport(PLC_IP, network=net, local_host=OUR_IP)
        async with session(tcp) as s:
            r = await s.request(0x01, 0x01, READ_D0_2, idempotent=True)
            assert r.data == bytes.fromhex("BEEF0102")
            assert tcp.local_node == 239 and tcp.remote_node == 10  # allocated by the server
            assert sim.tcp is not None and sim.tcp.connected_nodes == [239]
        assert net.stats.dropped == net.stats.overflows == 0


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_a_lost_datagram_costs_a_retransmission(backend: str) -> None:
    """The first command is lost: sent again after the first retransmission timeout (1/7
    of the call's 1 s: 2 retries, each wait doubling), answered at once then."""
    out: list[object] = []

    def fate(packet: Packet) -> Sequence[float]:
        return [] if packet.number == 1 else [0.0]

    async def main() -> None:
        async with (
            MemoryNetwork(fate=fate) as net,
            run_simulator(make_plc(), udp=(PLC_IP, 9600), network=net),
            session(UdpTransport(PLC_IP, network=net), timeout=1.0, retries=2) as s,
        ):
            r = await s.request(0x01, 0x01, READ_D0_2, idempotent=True)
            out.extend([r.data, anyio.current_time(), s.stats.retries, net.stats.dropped])

    run_on_virtual_time(main, backend)
    assert out == [bytes.fromhex("BEEF0102"), pytest.approx(1 / 7, abs=1e-6), 1, 1]


@pytest.mark.anyio
async def test_a_reset_fins_tcp_connection_is_a_lost_link_then_a_new_one(
    anyio_backend: object,
) -> None:
    async with (
        MemoryNetwork() as net,
        run_simulator(make_plc(), tcp=(PLC_IP, 9600), network=net),
        session(
            TcpTransport(PLC_IP, network=net), timeout=1.0, reconnect_backoff=(0.01, 0.01)
        ) as s,
    ):
        await s.request(0x01, 0x01, READ_D0_2, idempotent=True)
        (ours, theirs) = net.streams
        assert ours.remote == (PLC_IP, 9600) and theirs.remote == ours.local
        net.reset(ours)  # both ends broken
        with pytest.raises((ConnectionLost, FinsTimeout)):
            await s.request(0x01, 0x01, READ_D0_2)  # not idempotent: not sent again
        r = await s.request(0x01, 0x01, READ_D0_2, idempotent=True)
        assert r.data == bytes.fromhex("BEEF0102")
        assert s.stats.connects == 2


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_udp_over_the_network_runs_on_virtual_time(backend: str) -> None:
    """Replies 0.25 s late, timeout 1 s: each read completes at exactly +0.25 s; a silent
    PLC (every reply lost) fails a read at exactly +1 s."""
    times: list[float] = []

    async def main() -> None:
        async with (
            MemoryNetwork(fate=lambda p: [0.125]) as net,
            run_simulator(make_plc(), udp=(PLC_IP, 9600), network=net),
            session(UdpTransport(PLC_IP, network=net), timeout=1.0, retries=0) as s,
        ):
            for _ in range(3):
                await s.request(0x01, 0x01, READ_D0_2)
                times.append(anyio.current_time())
            net.fate = lambda p: [] if p.source[1] == 9600 else [0.125]
            with pytest.raises(FinsTimeout):
                await s.request(0x01, 0x01, READ_D0_2)
            times.append(anyio.current_time())

    run_on_virtual_time(main, backend)
    assert times == [0.25, 0.5, 0.75, 1.75]
