"""Session over Host Link FINS through a socat pty pair (asyncio and trio).

The far end of the pty pair is an in-test Host Link responder reading and writing the raw fd.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import anyio
import pytest

from aiofins.protocol.errors import FinsTimeout
from aiofins.protocol.header import FinsAddress, ResponseFrame
from aiofins.protocol.hostlink import decode_command, encode_response
from aiofins.session import Session
from aiofins.transport import SerialTransport

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.serial,
    pytest.mark.skipif(shutil.which("socat") is None, reason="socat is not installed"),
]

#: Builds the reply line for a command line (None = stay silent).
LineHandler = Callable[[bytes], bytes | None]


def fcs(chars: bytes) -> int:
    value = 0
    for c in chars:
        value ^= c
    return value


def read_reply(line: bytes) -> bytes:
    """A normal 0101 reply: the word address, echoed as data."""
    cmd = decode_command(line)
    frame = cmd.frame
    word = int.from_bytes(frame.params[1:3], "big")
    data = (0x2000 | word).to_bytes(2, "big")
    return encode_response(
        ResponseFrame.reply_to(frame, 0, data), unit=cmd.unit, full_header=cmd.full_header
    )


@asynccontextmanager
async def hostlink_peer(path: str, handler: LineHandler) -> AsyncIterator[list[bytes]]:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    lines: list[bytes] = []
    try:
        async with anyio.create_task_group() as tg:

            async def serve() -> None:
                buf = b""
                while True:
                    await anyio.wait_readable(fd)
                    try:
                        buf += os.read(fd, 4096)
                    except BlockingIOError:
                        continue
                    while b"\r" in buf:
                        line, buf = buf.split(b"\r", 1)
                        line += b"\r"
                        lines.append(line)
                        answer = handler(line)
                        if answer is not None:
                            os.write(fd, answer)

            tg.start_soon(serve)
            yield lines
            tg.cancel_scope.cancel()
    finally:
        os.close(fd)


def serial_session(path: str, **options: object) -> Session:
    return Session(
        SerialTransport(path, baudrate=115200, unit=0, bytesize=8, parity="N", stopbits=1),
        source=FinsAddress(0, 0, 0),
        dest=FinsAddress(0, 0, 0),
        **options,  # type: ignore[arg-type]
    )


async def test_read_over_host_link(pty_pair: tuple[str, str]) -> None:
    plc, host = pty_pair
    async with hostlink_peer(plc, read_reply) as lines, serial_session(host) as session:
        response = await session.request(0x01, 0x01, bytes.fromhex("82000A000001"))
        assert response.data == bytes.fromhex("200A")
        # Short header form: @ UU FA W | ICF DA2 SA2 SID | MRC SRC params | FCS * CR
        sid = response.frame[9]
        text = b"@00FA0" + b"000000%02X" % sid + b"010182000A000001"
        assert lines[0] == text + b"%02X" % fcs(text) + b"*\r"


async def test_one_request_at_a_time_on_the_line(pty_pair: tuple[str, str]) -> None:
    plc, host = pty_pair
    async with hostlink_peer(plc, read_reply) as lines, serial_session(host) as session:
        results: dict[int, bytes] = {}

        async def one(word: int) -> None:
            params = bytes((0x82, 0, word, 0, 0, 1))
            results[word] = (await session.request(0x01, 0x01, params, timeout=5)).data

        async with anyio.create_task_group() as tg:
            for word in range(6):
                tg.start_soon(one, word)
        assert results == {w: (0x2000 | w).to_bytes(2, "big") for w in range(6)}
        assert len(lines) == 6
        assert session.max_in_flight == 1


async def test_corrupted_fcs_is_counted_and_retried(pty_pair: tuple[str, str]) -> None:
    plc, host = pty_pair
    calls = 0

    def corrupt_first(line: bytes) -> bytes:
        nonlocal calls
        calls += 1
        good = read_reply(line)
        if calls == 1:
            bad_fcs = (int(good[-4:-2], 16) ^ 0x01).to_bytes(1, "big").hex().upper().encode()
            return good[:-4] + bad_fcs + b"*\r"
        return good

    async with (
        hostlink_peer(plc, corrupt_first) as lines,
        # The dropped reply's attempt waits a third of the call's 1.5 s, the retransmission
        # the rest: 1 s for a reply over the pty even on a loaded machine (with 0.2 s and two
        # retries, a retransmission waited 57 ms, and a loaded machine sent a third).
        serial_session(host, timeout=1.5, retries=1) as session,
    ):
        response = await session.request(0x01, 0x01, bytes.fromhex("820005000001"), idempotent=True)
        assert response.data == bytes.fromhex("2005")
        transport = session.transport
        assert isinstance(transport, SerialTransport)
        assert transport.frame_errors == 1
        assert session.stats.malformed == 1 and session.stats.retries == 1
        assert len(lines) == 2


async def test_silence_times_out(pty_pair: tuple[str, str]) -> None:
    plc, host = pty_pair
    async with hostlink_peer(plc, lambda line: None), serial_session(host, timeout=0.1) as s:
        with pytest.raises(FinsTimeout):
            await s.request(0x01, 0x01, bytes.fromhex("820000000001"))


async def test_routed_request_uses_the_full_header(pty_pair: tuple[str, str]) -> None:
    plc, host = pty_pair
    async with hostlink_peer(plc, read_reply) as lines, serial_session(host) as session:
        dest = FinsAddress(1, 5, 0)
        response = await session.request(0x01, 0x01, bytes.fromhex("820007000001"), dest=dest)
        assert response.data == bytes.fromhex("2007")
        # Full form: ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2 SID after "@00FA0".
        assert lines[0][6:24] == b"800002010500000000"


async def test_a_stray_at_sign_before_a_reply_is_skipped(pty_pair: tuple[str, str]) -> None:
    """The reply line ran from the first '@' and failed its FCS; it starts at the last one."""
    plc, host = pty_pair

    def noisy(line: bytes) -> bytes:
        return b"@0@" + read_reply(line)

    async with hostlink_peer(plc, noisy) as lines, serial_session(host, timeout=0.5) as session:
        response = await session.request(0x01, 0x01, bytes.fromhex("820005000001"))
        assert response.data == bytes.fromhex("2005")
        transport = session.transport
        assert isinstance(transport, SerialTransport)
        assert transport.frame_errors == 0 and session.stats.retries == 0
        assert len(lines) == 1
