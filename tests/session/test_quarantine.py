"""A quarantine ends on evidence that the PLC answers again, not on a fixed time (issue #22,
defect 4). On trio's virtual clock: the 18 s of each run take no wall time and every count
is exact."""

from __future__ import annotations

import anyio
import pytest
from trio.testing import MockClock

from aiofins.protocol.errors import FinsError
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.simulator import VirtualPLC
from aiofins.transport import MemoryTransport

pytestmark = pytest.mark.anyio

TIMEOUT = 0.2
READ_D0 = bytes((0x82, 0, 0, 0, 0, 1))


@pytest.fixture
def anyio_backend() -> object:
    """Virtual time: the session follows trio's MockClock."""
    return ("trio", {"clock": MockClock(autojump_threshold=0)})


@pytest.mark.parametrize(("readers", "breaker_threshold"), [(255, 0), (255, 5), (50, 5)])
async def test_after_1_2_s_of_silence_every_read_succeeds_again(
    readers: int, breaker_threshold: int
) -> None:
    """``max_sid_spaces=1`` (what a fixed-table PLC needs), ``readers`` tasks reading every
    50 ms, each request given up after 0.2 s. 1.2 s of silence gave up on every SID in
    flight, each quarantined for ``min_quarantine`` (15 s); with 255 in flight every SID
    was, and no read could even be sent for 15 s: 384 good reads a second instead of 5,100
    (issue #22, defect 4). Now the first answer to a request sent after they were given
    up on ends those quarantines (0.5 s later), and while every SID is quarantined a probe
    under the oldest one (another command: a late reply to the old one cannot match it)
    asks whether the PLC answers again."""
    plc = VirtualPLC()
    silent = False

    def handler(frame: bytes) -> bytes | None:
        return None if silent else plc.handle_frame(frame)

    good: list[float] = []
    failed: list[float] = []
    async with Session(
        MemoryTransport(handler),
        source=FinsAddress(0, 254, 0),
        dest=FinsAddress(0, 1, 0),
        max_sid_spaces=1,
        timeout=TIMEOUT,
        retries=0,
        max_in_flight=readers,
        breaker_threshold=breaker_threshold,
    ) as session:
        start = anyio.current_time()

        async def reader() -> None:
            while anyio.current_time() - start < 18.0:
                try:
                    await session.request(0x01, 0x01, READ_D0, idempotent=True)
                except FinsError:
                    failed.append(anyio.current_time() - start)
                else:
                    good.append(anyio.current_time() - start)
                await anyio.sleep(0.05)

        async with anyio.create_task_group() as tg:
            for _ in range(readers):
                tg.start_soon(reader)
            await anyio.sleep(1.0)
            silent = True
            await anyio.sleep(1.2)
            silent = False
            back = anyio.current_time() - start
            # the recovery bound of docs/session.md: 2 x the timeout + the longest cooldown
            await anyio.sleep(2 * TIMEOUT + 2.0)
            now = anyio.current_time()
            assert [u for u in session._quarantine.values() if u > now] == []
        recovered = back + 2 * TIMEOUT + 2.0
        assert [t for t in failed if t > recovered] == []
        assert len([t for t in good if t > recovered]) >= readers * int((18.0 - recovered) / 0.06)
        probes = session.stats.sid_probes  # (one per timeout while every SID is given up on)
        assert probes >= 1 if readers == 255 else probes == 0
