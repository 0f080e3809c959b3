"""``Transport.another()``: a second socket (UDP) or connection (FINS/TCP) to the same peer,
another SID space the first one's replies cannot reach."""

from __future__ import annotations

import anyio
import pytest

from aiofins.protocol.tcp import DEFAULT_PORT
from aiofins.session.background import Background
from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.transport import MemoryTransport, SerialTransport, TcpTransport, UdpTransport
from aiofins.transport.base import Transport

from ..session.test_session_udp import answer, read_params, udp_responder

pytestmark = pytest.mark.anyio


class Sink:
    """Collects what a transport pushes."""

    def __init__(self) -> None:
        self.frames: list[bytes] = []
        self.lost: list[BaseException | None] = []

    def frame_received(self, frame: bytes, _addr: object = None, /) -> None:
        self.frames.append(frame)

    def frame_dropped(self, reason: str) -> None:  # pragma: no cover - not expected here
        raise AssertionError(reason)

    def connection_lost(self, exc: BaseException | None) -> None:
        self.lost.append(exc)


def command(source_node: int, sid: int, word: int) -> bytes:
    """A 0101 read of DM ``word`` from node ``source_node`` to node 1, SID ``sid``."""
    header = bytes((0x80, 0, 2, 0, 1, 0, 0, source_node, 0, sid))
    return header + bytes((0x01, 0x01)) + read_params(word)


async def wait_for(sink: Sink, count: int) -> None:
    with anyio.fail_after(5):
        while len(sink.frames) < count:
            await anyio.sleep(0.005)


async def test_another_udp_transport_is_a_socket_of_its_own_to_the_same_peer() -> None:
    async with udp_responder(answer) as peer, anyio.create_task_group() as tg:
        first = UdpTransport("localhost", peer.port)
        second = first.another()
        assert isinstance(second, UdpTransport) and second is not first
        assert not second.is_open
        sinks = Sink(), Sink()
        await first.open(sinks[0], Background(tg))
        await second.open(sinks[1], Background(tg))
        try:
            assert first.peer_link == second.peer_link == f"udp://127.0.0.1:{peer.port}"
            assert first.local_address != second.local_address
            await first.send(command(254, 7, 10))
            await second.send(command(253, 7, 11))  # the same SID: another space
            await wait_for(sinks[0], 1)
            await wait_for(sinks[1], 1)
            assert [f[4] for f in (sinks[0].frames[0], sinks[1].frames[0])] == [254, 253]  # DA1
            assert sinks[0].frames[0][-2:] == (0x100A).to_bytes(2, "big")
            assert sinks[1].frames[0][-2:] == (0x100B).to_bytes(2, "big")
            assert len(sinks[0].frames) == len(sinks[1].frames) == 1
        finally:
            await first.aclose()
            await second.aclose()
        assert first.peer_link is None


async def test_another_fins_tcp_transport_is_a_connection_with_a_node_of_its_own() -> None:
    plc = VirtualPLC()
    plc.memory.write_words(0x82, 10, [0x1234])
    async with (
        run_simulator(plc, tcp=("127.0.0.1", 0)) as sim,
        anyio.create_task_group() as tg,
    ):
        first = TcpTransport("127.0.0.1", sim.tcp_port, node=5, connect_timeout=2)
        second = first.another()
        assert isinstance(second, TcpTransport)
        assert (second.node, second.connect_timeout) == (0, 2)  # the PLC allocates its node
        sinks = Sink(), Sink()
        await first.open(sinks[0], Background(tg))
        await second.open(sinks[1], Background(tg))
        try:
            assert first.local_node == 5
            assert second.local_node is not None and second.local_node not in (5, 1)
            await second.send(command(second.local_node, 0, 10))
            await wait_for(sinks[1], 1)
            assert sinks[1].frames[0][4] == second.local_node  # DA1: the new connection's
            assert sinks[1].frames[0][-2:] == (0x1234).to_bytes(2, "big")
            assert sinks[0].frames == []
        finally:
            await first.aclose()
            await second.aclose()


def test_which_media_have_more_sid_spaces() -> None:
    udp, tcp = UdpTransport("127.0.0.1"), TcpTransport("127.0.0.1")
    serial = SerialTransport("/dev/null")
    memory = MemoryTransport(VirtualPLC().handle_frame, name="m")
    assert (udp.default_sid_spaces, udp.own_source_node) == (4, True)
    assert (tcp.default_sid_spaces, tcp.own_source_node, tcp.port) == (2, False, DEFAULT_PORT)
    assert (serial.default_sid_spaces, serial.another()) == (1, None)
    other = memory.another()
    assert isinstance(other, MemoryTransport) and other.handler == memory.handler
    assert other.description == "memory://m" and memory.default_sid_spaces == 1
    assert Transport.another(udp) is None  # the contract's default: one link
