"""The manual's corner cases answered over real UDP and FINS/TCP, asserted on raw bytes.

Frames are built by hand here (not by aiofins' client): 10-byte header, command code,
parameters.
"""

from __future__ import annotations

import struct
from collections.abc import AsyncIterator, Awaitable, Callable

import anyio
import pytest

from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import run_simulator
from aiofins.simulator.state import Mode

pytestmark = pytest.mark.anyio

Exchange = Callable[[bytes], Awaitable[bytes]]


def command(sid: int, code: str, params: str = "", *, src_node: int = 0x22) -> bytes:
    # ICF 80, RSV 00, GCT 02, DNA 00 DA1 01 DA2 00, SNA 00 SA1 src SA2 00, SID
    return bytes((0x80, 0, 2, 0, 1, 0, 0, src_node, 0, sid)) + bytes.fromhex(code + params)


@pytest.fixture(params=["udp", "tcp"])
async def exchange(
    request: pytest.FixtureRequest, anyio_backend: object
) -> AsyncIterator[tuple[VirtualPLC, Exchange]]:
    plc = VirtualPLC(mode=Mode.PROGRAM)
    async with run_simulator(plc, udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0)) as sim:
        if request.param == "udp":
            async with await anyio.create_connected_udp_socket("127.0.0.1", sim.udp_port) as udp:

                async def over_udp(frame: bytes) -> bytes:
                    await udp.send(frame)
                    with anyio.fail_after(10):  # a hang guard (a loaded machine is slow)
                        return await udp.receive()

                yield plc, over_udp
            return
        async with await anyio.connect_tcp("127.0.0.1", sim.tcp_port) as tcp:
            # Node address request: FINS, length 12, command 0, error 0, client node 0.
            await tcp.send(b"FINS" + struct.pack(">IIII", 12, 0, 0, 0))
            reply = await _receive_exactly(tcp, 24)
            assert reply[:16] == b"FINS" + struct.pack(">III", 16, 1, 0)
            client_node = reply[19]

            async def over_tcp(frame: bytes) -> bytes:
                frame = frame[:7] + bytes((client_node,)) + frame[8:]  # SA1 = our node
                await tcp.send(b"FINS" + struct.pack(">III", 8 + len(frame), 2, 0) + frame)
                head = await _receive_exactly(tcp, 16)
                length = struct.unpack(">I", head[4:8])[0]
                body = await _receive_exactly(tcp, length - 8)
                return body[:4] + b"\x22" + body[5:]  # as if our node were 0x22

            yield plc, over_tcp


async def _receive_exactly(stream: anyio.abc.ByteStream, n: int) -> bytes:
    data = b""
    with anyio.fail_after(10):  # a hang guard (a loaded machine is slow)
        while len(data) < n:
            data += await stream.receive(n - len(data))
    return data


def header_ok(reply: bytes, sid: int) -> None:
    # ICF C0, RSV 00, GCT 02, to 00.22.00 from 00.01.00, same SID.
    assert reply[0] == 0xC0 and reply[3:10] == bytes((0, 0x22, 0, 0, 1, 0, sid))


async def test_count_zero_is_a_normal_response_with_no_data(
    exchange: tuple[VirtualPLC, Exchange],
) -> None:
    _, send = exchange
    reply = await send(command(1, "0101", "820064000000"))
    header_ok(reply, 1)
    assert reply[10:] == bytes.fromhex("01010000")


async def test_write_then_read_words_bytes(exchange: tuple[VirtualPLC, Exchange]) -> None:
    _, send = exchange
    assert (await send(command(2, "0102", "82000A0000021234ABCD")))[10:] == bytes.fromhex(
        "01020000"
    )
    assert (await send(command(3, "0101", "82000A000002")))[10:] == bytes.fromhex(
        "010100001234ABCD"
    )


async def test_read_only_auxiliary_area_answers_2101(
    exchange: tuple[VirtualPLC, Exchange],
) -> None:
    _, send = exchange
    assert (await send(command(4, "0102", "B300000000010001")))[10:] == bytes.fromhex("01022101")


async def test_run_without_mode_goes_to_monitor(exchange: tuple[VirtualPLC, Exchange]) -> None:
    plc, send = exchange
    assert (await send(command(5, "0401", "FFFF")))[10:] == bytes.fromhex("04010000")
    assert plc.mode is Mode.MONITOR
    status = await send(command(6, "0601"))
    assert status[10:14] == bytes.fromhex("06010000") and status[15] == 0x02  # MONITOR


async def test_access_right_held_elsewhere_names_the_holder(
    exchange: tuple[VirtualPLC, Exchange],
) -> None:
    plc, send = exchange
    await send(command(7, "0C01", "FFFF"))  # we take it
    holder = plc.access_holder
    assert holder is not None
    # Another node asks: 3001 and the holder's network, node and unit.
    other = plc.handle_frame(command(8, "0C01", "FFFF", src_node=0x33))
    assert other is not None
    assert other[10:] == bytes.fromhex("0C013001") + bytes(
        (holder.network, holder.node, holder.unit)
    )


async def test_parameter_read_over_498_words_answers_1108_with_498(
    exchange: tuple[VirtualPLC, Exchange],
) -> None:
    _, send = exchange
    reply = await send(command(9, "0201", "8010000001F4"))  # 500 words
    assert reply[10:14] == bytes.fromhex("02011108")
    assert reply[14:16] == bytes.fromhex("8010") and reply[18:20] == bytes.fromhex("01F2")
    assert len(reply[20:]) == 498 * 2


async def test_undefined_command_answers_0401(exchange: tuple[VirtualPLC, Exchange]) -> None:
    _, send = exchange
    assert (await send(command(10, "0199")))[10:] == bytes.fromhex("01990401")
