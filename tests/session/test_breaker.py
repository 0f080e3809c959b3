"""The circuit breaker's probe: every call that takes it reports how it ended, on every path
(``request``, ``request_many`` on the batch and on the portable path, the Poller's), so a
breaker never stays open once the PLC answers again (issue #22, defect 1)."""

from __future__ import annotations

from collections.abc import Callable

import anyio
import looptime
import pytest
from trio.testing import MockClock

import aiofins
from aiofins.protocol.errors import CircuitOpen, FinsError
from aiofins.session.breaker import BreakerState
from aiofins.simulator import VirtualPLC
from aiofins.transport import MemoryTransport

pytestmark = pytest.mark.anyio


@pytest.fixture(
    params=[
        pytest.param(("trio", {"clock": MockClock(autojump_threshold=0)}), id="trio-virtual"),
        pytest.param(("asyncio", {}), id="asyncio-virtual"),
    ]
)
def anyio_backend(request: pytest.FixtureRequest) -> object:
    """trio and asyncio on virtual time (the session follows the loop's clock: the 6 s of
    each test take no wall time and the recovery bound is checked exactly): trio's
    MockClock, asyncio on looptime's loop (the Poller's callback and batch paths);
    uvloop's clock cannot be virtual."""
    if request.param[0] == "trio":  # a fresh clock for each test
        return ("trio", {"clock": MockClock(autojump_threshold=0)})
    return ("asyncio", {"loop_factory": lambda: looptime.new_event_loop(start=0.0)})


DM = 0x82
TIMEOUT = 0.2
COOLDOWN = (0.05, 2.0)  # the default breaker_cooldown
CALLS = 100  # after the PLC answers again, 50 ms apart
#: The calls that may fail after the PLC answers again: the recovery bound (docs/session.md)
#: of 2 x the timeout plus the breaker's longest cooldown, at one call per 50 ms.
MAY_FAIL = (2 * TIMEOUT + COOLDOWN[1]) / 0.05
READ_D0 = (0x01, 0x01, bytes([DM, 0, 0, 0, 0, 1]))
READ_D1 = (0x01, 0x01, bytes([DM, 0, 1, 0, 0, 1]))


class FaultyPLC:
    """A virtual PLC behind a switch: ``"silent"`` (no reply), ``"wrong_sid"`` (every reply
    under another SID), ``"runt"`` (11-byte replies) or ``"normal"``."""

    def __init__(self) -> None:
        self.plc = VirtualPLC()
        self.plc.memory.write_words(DM, 0, [10, 11, 12, 13])
        self.mode = "normal"

    def __call__(self, frame: bytes) -> bytes | None:
        if self.mode == "silent":
            return None
        reply = self.plc.handle_frame(frame)
        if reply is None:
            return None
        if self.mode == "wrong_sid":
            return reply[:9] + bytes([reply[9] ^ 0x80]) + reply[10:]
        if self.mode == "runt":
            return reply[:11]
        return reply


async def _outage_then_normal(
    plc: FaultyPLC, call: Callable[[], object], second_fault: str
) -> tuple[int, int, float]:
    """The issue's sequence, one call every 50 ms: 0.6 s of silence, 0.6 s of ``second_fault``,
    then a PLC that answers normally for 5 s. The calls that failed after that point, the
    number that succeeded, and the time from that point to the first success."""
    for mode in ("silent", second_fault):
        plc.mode = mode
        end = anyio.current_time() + 0.6
        while anyio.current_time() < end:
            with pytest.raises(FinsError):
                await call()  # type: ignore[misc]
            await anyio.sleep(0.05)
    plc.mode = "normal"
    back = anyio.current_time()
    first_good = -1.0
    failed = good = 0
    for _ in range(CALLS):
        try:
            await call()  # type: ignore[misc]
        except CircuitOpen:
            failed += 1
        else:
            good += 1
            if first_good < 0:
                first_good = anyio.current_time() - back
        await anyio.sleep(0.05)
    return failed, good, first_good


@pytest.mark.parametrize("second_fault", ["wrong_sid", "runt"])
@pytest.mark.parametrize("commands", [1, 2])
async def test_a_breaker_opened_by_an_outage_closes_for_request_many(
    second_fault: str, commands: int
) -> None:
    """``request_many`` (what the Poller's scans and ``read_tags`` use) after an outage:
    the call that takes the probe sends its commands, so the breaker closes. Before the fix
    the portable path's own ``request`` calls were turned away by their call's probe, and
    every call failed with CircuitOpen for ever (100 of 100)."""
    plc = FaultyPLC()
    async with aiofins.connect(
        transport=MemoryTransport(plc),
        timeout=TIMEOUT,
        retries=0,
    ) as client:
        session = client.session
        batch = [READ_D0, READ_D1][:commands]

        async def call() -> None:
            responses = await session.request_many(batch, idempotent=True)
            assert [r.data for r in responses] == [b"\x00\x0a", b"\x00\x0b"][:commands]

        failed, good, first_good = await _outage_then_normal(plc, call, second_fault)
        assert good + failed == CALLS and failed <= MAY_FAIL and first_good >= 0
        assert session.breaker_state is BreakerState.CLOSED
        assert first_good <= 2 * TIMEOUT + COOLDOWN[1]  # the recovery bound of docs/session.md


async def test_a_breaker_opened_by_an_outage_closes_for_read_tags() -> None:
    """The Poller's task path: ``read_tags`` of a plan read by one multiple-area read."""
    plc = FaultyPLC()
    async with aiofins.connect(
        transport=MemoryTransport(plc),
        timeout=TIMEOUT,
        retries=0,
    ) as client:
        plc.plc.memory.write_words(DM, 1000, [20])
        plan = client.compile_tags({"a": "D0", "b": "D1000", "c": "D2:int16", "d": "D3000"})
        assert len(plan.multiple) == 1 and not plan.runs  # one 0104 frame

        async def call() -> None:
            assert await client.read_tags(plan) == {"a": 10, "b": 20, "c": 12, "d": 0}

        failed, good, _ = await _outage_then_normal(plc, call, "wrong_sid")
        assert good + failed == CALLS and failed <= MAY_FAIL
        assert client.session.breaker_state is BreakerState.CLOSED
