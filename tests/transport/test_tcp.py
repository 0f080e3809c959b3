"""FINS/TCP transport: the handshake's fields checked, a bad one a typed error of its own
connection attempt (never an exception out of a background task), the connect deadline."""

from __future__ import annotations

import pytest

import aiofins
from aiofins.protocol.errors import ConnectionLost, FinsError, FrameError

from ..session.test_session_tcp import TcpPeer, tcp_server

pytestmark = pytest.mark.anyio


@pytest.mark.parametrize("node", [0, 255, 300, 0x10000])
async def test_a_first_handshake_assigning_a_bad_client_node_fails_connect(node: int) -> None:
    async with tcp_server(TcpPeer(assign_node=node)) as peer:
        with pytest.raises(FrameError, match=f"client node {node}, out of range 1..254"):
            async with aiofins.connect(f"tcp://127.0.0.1:{peer.port}"):
                pytest.fail("connected")  # pragma: no cover
        assert peer.requested_nodes == [0]


async def test_a_handshake_naming_server_node_0_fails_connect() -> None:
    async with tcp_server(TcpPeer(server_node=0)) as peer:
        with pytest.raises(FrameError, match="server node 0, out of range"):
            async with aiofins.connect(f"tcp://127.0.0.1:{peer.port}"):
                pytest.fail("connected")  # pragma: no cover


async def test_a_reconnect_assigning_node_300_is_a_typed_error_of_the_call() -> None:
    """#17 item 2: the reconnect's handshake names client node 300. The call gets a
    FrameError, the attempt is counted as failed (never as a connect first), and the
    ``async with`` goes on (it used to die with an ExceptionGroup from the connect task)."""
    async with tcp_server(TcpPeer(assign_node=0x21)) as peer:
        url = f"tcp://127.0.0.1:{peer.port}"
        async with aiofins.connect(url, timeout=2, retries=0) as plc:
            stats = plc.session.stats
            assert await plc.read("D10", 2) == [0x100A, 0x100B]
            peer.assign_node = 300
            await peer.drop()
            errors: list[FinsError] = []
            for _ in range(3):  # the first call may still meet the dropped connection
                with pytest.raises(FinsError) as info:
                    await plc.read("D10", 2)
                errors.append(info.value)
                if not isinstance(info.value, ConnectionLost):
                    break
            assert isinstance(errors[-1], FrameError), errors
            assert str(errors[-1]) == (
                f"{url}: FINS/TCP node address reply names client node 300, out of range 1..254"
            )
            assert all(isinstance(e, ConnectionLost) for e in errors[:-1])
            assert peer.requested_nodes == [0, 0]
            assert (stats.connects, stats.connect_failures) == (1, 1)
            assert plc.session.source.node == 0x21
