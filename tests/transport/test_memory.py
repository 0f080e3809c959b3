"""The in-memory transport: a client and session over a virtual PLC, no socket."""

from __future__ import annotations

import anyio
import pytest

import aiofins
from aiofins.protocol.errors import CommandError, ConnectionLost, EndCodeError, FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.simulator import VirtualPLC
from aiofins.transport import MemoryTransport, UdpTransport

pytestmark = pytest.mark.anyio

DM = 0x82


async def test_read_and_write_through_connect() -> None:
    plc = VirtualPLC()
    plc.memory.write_words(DM, 100, [7, 8, 9])
    transport = MemoryTransport(plc.handle_frame)
    async with aiofins.connect(transport=transport) as client:
        assert await client.read("D100", 3) == [7, 8, 9]
        await client.write("D200", [0x1234, 0xFFFF])
        assert plc.memory.read_words(DM, 200, 2) == [0x1234, 0xFFFF]
        assert client.session.dest == FinsAddress(0, 1, 0)
        assert client.session.source == FinsAddress(0, 254, 0)
    assert (transport.frames_sent, transport.replies) == (2, 2)
    assert not transport.is_open
    assert transport.description == "memory://memory"


async def test_many_requests_in_flight_and_request_many() -> None:
    plc = VirtualPLC()
    plc.memory.write_words(DM, 0, list(range(1000)))
    transport = MemoryTransport(plc.handle_frame, name="plc-a")
    async with aiofins.connect(transport=transport, max_in_flight=5) as client:
        got: dict[int, list[int]] = {}

        async def one(word: int) -> None:
            got[word] = await client.read(f"D{word}", 2)

        async with anyio.create_task_group() as tg:
            for word in range(0, 100, 2):
                tg.start_soon(one, word)
        assert got == {w: [w, w + 1] for w in range(0, 100, 2)}
        # 1,000 words: two frames (999 + 1), pipelined through request_many under asyncio
        assert await client.read("D0", 1000) == list(range(1000))
        assert client.session.stats.malformed == 0


async def test_no_answer_times_out_and_handler_counts() -> None:
    asked: list[bytes] = []

    def silent(frame: bytes) -> None:
        asked.append(frame)

    async with aiofins.connect(transport=MemoryTransport(silent), timeout=0.05, retries=1) as c:
        with pytest.raises(FinsTimeout, match="memory://memory"):
            await c.read("D0", 1)
    assert len(asked) == 2  # the first attempt and one retry
    assert asked[0][10:12] == b"\x01\x01"


async def test_a_hand_written_handler_answering_an_end_code() -> None:
    def busy(frame: bytes) -> bytes:
        # The reply swaps the addresses and keeps the SID and command code (wire-format §2).
        header = bytes([0xC0, 0, 2, *frame[6:9], *frame[3:6], frame[9]])
        return header + frame[10:12] + b"\x11\x03"  # 1103: address range exceeded

    async with aiofins.connect(transport=MemoryTransport(busy)) as client:
        with pytest.raises(EndCodeError) as info:
            await client.read("D0", 1)
    assert info.value.code == 0x1103


async def test_a_lost_link_fails_what_is_in_flight_and_reopens() -> None:
    plc = VirtualPLC()
    sent = anyio.Event()

    def hold(frame: bytes) -> None:
        sent.set()

    transport = MemoryTransport(hold)
    async with aiofins.connect(transport=transport, timeout=5, retries=0) as client:
        async with anyio.create_task_group() as tg:

            async def call() -> None:
                with pytest.raises(ConnectionLost, match="the link was lost"):
                    await client.read("D0", 1)

            tg.start_soon(call)
            await sent.wait()
            transport.lose_connection()
        assert not transport.is_open
        transport.handler = plc.handle_frame
        assert await client.read("D0", 1) == [0]  # opened again
        assert client.session.stats.connects == 2


async def test_connect_refuses_a_url_and_a_transport_or_neither() -> None:
    plc = VirtualPLC()
    with pytest.raises(CommandError, match="a URL or transport=, not both"):
        async with aiofins.connect("udp://127.0.0.1", transport=MemoryTransport(plc.handle_frame)):
            pass  # pragma: no cover
    with pytest.raises(CommandError, match=r"URL must be text \(or give transport=\); got None"):
        async with aiofins.connect():
            pass  # pragma: no cover
    with pytest.raises(CommandError, match="tcp_node"):
        async with aiofins.connect(transport=MemoryTransport(plc.handle_frame), tcp_node=3):
            pass  # pragma: no cover
    with pytest.raises(CommandError, match="must be a Transport, got method"):
        async with aiofins.connect(transport=plc.handle_frame):  # type: ignore[arg-type]
            pass  # pragma: no cover
    assert isinstance(UdpTransport("127.0.0.1"), aiofins.transport.Transport)


def test_pool_does_not_take_a_transport() -> None:
    with pytest.raises(CommandError, match="unknown option"):
        aiofins.Pool(transport=MemoryTransport(VirtualPLC().handle_frame))
