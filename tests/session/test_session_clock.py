"""The session's one clock: every part reads the event loop's time, so under trio's
``MockClock(autojump_threshold=0)`` a 10 s outage takes no wall time and its timing is
exact (see aiofins/session/clock.py)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

import anyio
import pytest
import trio
import trio.testing

from aiofins.protocol.errors import CircuitOpen, FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.session.breaker import BreakerState
from aiofins.session.clock import backend_clocks
from aiofins.simulator import VirtualPLC
from aiofins.transport import MemoryTransport

from ..virtual_time import VIRTUAL_BACKENDS, run_on_virtual_time

SOURCE, DEST = FinsAddress(0, 2, 0), FinsAddress(0, 1, 0)
READ_D0 = bytes.fromhex("820000000001")  # 0101: DM 0, one word


def silent_plc(plc: VirtualPLC, silent: Callable[[float], bool]) -> Callable[[bytes], bytes | None]:
    """``plc``'s handler, answering nothing while ``silent(now)`` (the loop's clock)."""

    def handle(frame: bytes) -> bytes | None:
        return None if silent(anyio.current_time()) else plc.handle_frame(frame)

    return handle


def now() -> float:
    """The running backend's clock."""
    return anyio.current_time()


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_a_plc_silent_for_10_s_fails_each_read_at_its_deadline_and_answers_at_once(
    backend: str,
) -> None:
    """Breaker off: each read of the outage fails exactly 1 s (its timeout) after it began,
    after 3 transmissions; the first read once the PLC answers again succeeds at once, at
    exactly t = 10 s. No wall time passes for the 10 virtual seconds (trio's MockClock;
    asyncio on looptime's virtual-time loop, whose loop.time the session takes)."""
    plc = VirtualPLC()
    plc.memory.write_words(0x82, 0, [0x1234])
    transport = MemoryTransport(silent_plc(plc, lambda t: t < 10.0))
    failures: list[tuple[float, int]] = []
    answered: list[tuple[float, bytes]] = []

    async def main() -> None:
        assert now() == 0.0
        async with Session(
            transport, source=SOURCE, dest=DEST, timeout=1.0, retries=2, breaker_threshold=0
        ) as session:
            if backend == "trio":
                assert session.clock == trio.lowlevel.current_clock().current_time
            else:
                assert session.clock == asyncio.get_running_loop().time
            while not answered:
                try:
                    r = await session.request(0x01, 0x01, READ_D0, idempotent=True)
                except FinsTimeout as exc:
                    assert "in 3 attempts" in str(exc), exc
                    failures.append((now(), session.stats.timeouts))
                else:
                    answered.append((now(), r.data))
            assert session.stats.timeouts == 10
            assert session.stats.retries == 20
            assert len(session._quarantine) == 10

    run_on_virtual_time(main, backend)
    assert failures == [(float(t), t) for t in range(1, 11)]
    assert answered == [(10.0, bytes.fromhex("1234"))]
    assert transport.frames_sent == 10 * 3 + 1
    # (No wall-clock check that the 10 s were virtual: the exact times above show it.)


def test_the_breaker_opens_during_the_outage_and_a_probe_closes_it_after() -> None:
    """Breaker on (5 failures in a row, cooldown 0.05-2 s): after the 5th timeout (t = 5 s)
    calls fail at once with CircuitOpen, probes alone reach the PLC; once it answers
    (t = 10 s), a probe closes the breaker within one timeout plus the longest cooldown."""
    plc = VirtualPLC()
    transport = MemoryTransport(silent_plc(plc, lambda now: now < 10.0))
    events: list[tuple[float, str]] = []

    async def main() -> None:
        async with Session(
            transport,
            source=SOURCE,
            dest=DEST,
            timeout=1.0,
            retries=0,
            breaker_threshold=5,
            breaker_cooldown=(0.05, 2.0),
        ) as session:
            while True:
                try:
                    await session.request(0x01, 0x01, READ_D0, idempotent=True)
                except CircuitOpen as exc:
                    events.append((trio.current_time(), "open"))
                    await trio.sleep(max(exc.retry_after, 0.01))
                except FinsTimeout:
                    events.append((trio.current_time(), "timeout"))
                else:
                    events.append((trio.current_time(), "ok"))
                    break
            assert session.breaker_state is BreakerState.CLOSED

    run_on_virtual_time(main)
    timeouts = [t for t, what in events if what == "timeout"]
    assert timeouts[:5] == [1.0, 2.0, 3.0, 4.0, 5.0]  # then the breaker opens
    assert events[5][1] == "open" and events[5][0] == 5.0
    back, what = events[-1]
    assert what == "ok"
    assert 10.0 <= back <= 10.0 + 1.0 + 2.0
    # Open: only probes went out (one per cooldown, each waiting its 1 s), not a read per 10 ms.
    assert transport.frames_sent == len(timeouts) + 1
    assert len(timeouts) <= 5 + 5  # 5 s of outage left, each probe at least 1 s apart


@pytest.mark.anyio
async def test_the_session_reads_the_event_loop_s_clock(anyio_backend: object) -> None:
    """asyncio's own loop: time.monotonic (what its loop.time returns, without the Python
    call); uvloop: time.monotonic too (its loop.time is cached per turn at 1 ms); trio:
    the run's clock (what trio.current_time reads). A clock passed by the caller wins."""
    clocks = backend_clocks()
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        assert clocks.session == trio.lowlevel.current_clock().current_time and clocks.direct
    else:
        assert clocks.session is time.monotonic
        assert clocks.timer == loop.time
        assert clocks.direct is (type(loop).time is asyncio.BaseEventLoop.time)
    async with Session(
        MemoryTransport(VirtualPLC().handle_frame), source=SOURCE, dest=DEST
    ) as session:
        assert session.clock == clocks.session  # (a bound method: equal, not the same)
        assert session._link.clock is session.clock
        assert session.sids.clock is session.clock

    def mine() -> float:
        return 5.0 + anyio.current_time()

    async with Session(
        MemoryTransport(VirtualPLC().handle_frame), source=SOURCE, dest=DEST, clock=mine
    ) as session:
        assert session.clock is mine
        assert not session._watcher.direct
        r = await session.request(0x01, 0x01, READ_D0, idempotent=True)
        assert r.data == b"\x00\x00"
        with pytest.raises(FinsTimeout):  # the deadline is kept on the caller's clock
            await session.request(
                0x01, 0x01, READ_D0, idempotent=True, dest=FinsAddress(0, 9, 0), timeout=0.05
            )
