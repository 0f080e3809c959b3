"""Duplicates of replies and SID reuse (issue #22): what counts as a duplicate, and how a
copy of an old reply is told apart from a new reply after the SID was reused. On virtual
time (trio's MockClock, asyncio on looptime): every count is exact."""

from __future__ import annotations

import anyio
import pytest

from aiofins.protocol.errors import FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.simulator import VirtualPLC
from aiofins.transport import MemoryTransport

from ..virtual_time import on_virtual_time


def read_d(word: int) -> bytes:
    """0101 parameters: one DM word."""
    return bytes((0x82, word >> 8, word & 0xFF, 0, 0, 1))


@on_virtual_time
async def test_a_reply_with_a_wrong_sid_is_no_duplicate_and_teaches_no_linger() -> None:
    """A reply under a SID answered 2 s earlier that is not a copy of that SID's reply (the
    PLC answered with a wrong SID) is unsolicited. Counted as a duplicate 2 s late, it made
    every SID answered within 4 s linger 4 s: 300 reads right after the PLC answered
    normally again found no free SID after the 255th (the soak's seeds 20047, 20210,
    20237, 20428 and 20499: no free SID long after the faults)."""
    plc = VirtualPLC()
    plc.write("D0", range(1000, 1600))  # each word its own value
    wrong_sid = False

    def handler(frame: bytes) -> bytes | None:
        reply = plc.handle_frame(frame)
        if reply is None or not wrong_sid:
            return reply
        return reply[:9] + bytes((reply[9] ^ 0x80,)) + reply[10:]

    async with Session(
        MemoryTransport(handler),
        source=FinsAddress(0, 254, 0),
        dest=FinsAddress(0, 1, 0),
        max_sid_spaces=1,
        timeout=0.2,
        retries=0,
    ) as session:
        for word in range(256):  # every SID answered once
            await session.request(0x01, 0x01, read_d(word))
        await anyio.sleep(2.0)
        wrong_sid = True
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read_d(256))
        wrong_sid = False
        for word in range(300):
            assert (await session.request(0x01, 0x01, read_d(word))).data == (1000 + word).to_bytes(
                2, "big"
            )
        stats = session.stats
        assert (stats.duplicates, stats.unsolicited, stats.completed) == (0, 1, 556)
        assert session.sids.linger == 0.0 and stats.sid_exhausted == 0
