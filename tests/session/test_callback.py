"""start_requests: requests whose outcome goes to a callback, over real loopback UDP/TCP
(asyncio and uvloop; under trio it declines and the awaitable path does the work)."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest

from aiofins.protocol.errors import (
    CircuitOpen,
    ConnectionLost,
    EndCodeError,
    FinsTimeout,
)
from aiofins.session import Response, Session
from aiofins.session.breaker import BreakerState
from aiofins.session.callback import CallbackBatch, start_requests
from aiofins.transport.base import is_asyncio

from ..virtual_time import on_virtual_time
from .test_request_many import assert_idle, expected, key_of, reads
from .test_session_udp import Reply, answer, read_params, reply, session_for, udp_responder

pytestmark = pytest.mark.anyio

Outcome = tuple[list[Response] | None, BaseException | None]


class Done:
    """The callback: records each outcome and wakes the test."""

    def __init__(self) -> None:
        self.outcomes: list[Outcome] = []
        self.event = anyio.Event()

    def __call__(self, responses: list[Response] | None, error: BaseException | None) -> None:
        self.outcomes.append((responses, error))
        self.event.set()

    async def outcome(self, within: float = 5.0) -> Outcome:
        with anyio.fail_after(within):
            await self.event.wait()
        assert len(self.outcomes) == 1
        return self.outcomes[0]


@asynccontextmanager
async def on_asyncio_only() -> AsyncIterator[None]:
    if not is_asyncio():
        pytest.skip("the callback path is asyncio's (trio: see test_trio_declines...)")
    yield


def started(batch: CallbackBatch | None) -> CallbackBatch:
    assert batch is not None, "start_requests declined"
    return batch


async def test_responses_come_to_the_callback_with_their_data() -> None:
    async with on_asyncio_only(), udp_responder() as peer, session_for(peer) as s:
        done = Done()
        started(start_requests(s, reads(range(100, 103)), done))
        assert done.outcomes == []  # never from inside start_requests
        responses, error = await done.outcome()
        assert error is None and responses is not None
        assert [r.data for r in responses] == [expected(w) for w in range(100, 103)]
        assert [cmd[10:] for cmd in peer.received] == [
            b"\x01\x01" + read_params(w) for w in range(100, 103)
        ]
        assert s.stats.completed == 3
        assert_idle(s)


async def test_trio_declines_and_the_awaitable_path_reads() -> None:
    if is_asyncio():
        pytest.skip("trio only")
    async with udp_responder() as peer, session_for(peer) as s:
        done = Done()
        assert start_requests(s, reads(range(5)), done) is None
        responses = await s.request_many(reads(range(5)), idempotent=True)
        assert [r.data for r in responses] == [expected(w) for w in range(5)]
        assert done.outcomes == [] and not peer.received[5:]


@on_virtual_time  # counts transmissions: on the wall clock a loaded machine's late reply
# was sent again after the retransmission timeout (uvloop: its clock cannot be virtual)
async def test_a_dropped_request_is_sent_again_with_the_same_frame() -> None:
    seen = 0

    def drop_first(cmd: bytes) -> list[Reply]:
        nonlocal seen
        seen += 1
        return [] if seen == 1 else answer(cmd)

    async with (
        on_asyncio_only(),
        udp_responder(drop_first) as peer,
        session_for(peer, rto_bounds=(0.05, 0.1)) as s,
    ):
        done = Done()
        started(start_requests(s, reads(range(7, 8)), done, timeout=2.0))
        responses, error = await done.outcome()
        assert error is None and responses is not None and responses[0].data == expected(7)
        assert len(peer.received) == 2 and peer.received[0] == peer.received[1]
        assert s.stats.retries == 1
        assert_idle(s)


@on_virtual_time  # short timeouts, silent or late peer (uvloop: its clock cannot be virtual)
async def test_no_reply_fails_as_a_timeout_and_quarantines_the_sid() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: []) as peer,
        session_for(peer, retries=1) as s,
    ):
        done = Done()
        started(start_requests(s, reads(range(1)), done, timeout=0.2))
        responses, error = await done.outcome()
        assert responses is None and isinstance(error, FinsTimeout)
        assert "no response to command 0101" in str(error) and "in 2 attempts" in str(error)
        assert len(peer.received) == 2
        assert key_of(peer.received[0]) in s.sids.quarantine
        assert s.stats.timeouts == 1
        assert_idle(s)


@on_virtual_time  # short timeouts, silent or late peer (uvloop: its clock cannot be virtual)
async def test_a_late_reply_is_dropped_and_counted() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: [(0.3, reply(cmd, 0, b"\x00\x01"))]) as peer,
        session_for(peer, retries=0) as s,
    ):
        done = Done()
        started(start_requests(s, reads(range(1)), done, timeout=0.1))
        _, error = await done.outcome()
        assert isinstance(error, FinsTimeout)
        with anyio.fail_after(5):
            while not s.stats.late_replies:
                await anyio.sleep(0.01)
        assert len(done.outcomes) == 1  # the late reply reached nobody
        assert peer.received and s.stats.completed == 0


async def test_busy_end_codes_are_retried_with_a_fresh_sid() -> None:
    calls = 0

    def busy_twice(cmd: bytes) -> list[Reply]:
        nonlocal calls
        calls += 1
        return [(0.0, reply(cmd, 0x2604))] if calls <= 2 else answer(cmd)

    async with (
        on_asyncio_only(),
        udp_responder(busy_twice) as peer,
        session_for(peer, busy_backoff=0.001) as s,
    ):
        done = Done()
        started(start_requests(s, reads(range(9, 10)), done))
        responses, error = await done.outcome()
        assert error is None and responses is not None and responses[0].data == expected(9)
        assert s.stats.busy_retries == 2
        assert len({cmd[9] for cmd in peer.received}) == 3
        assert_idle(s)


async def test_an_end_code_fails_with_its_error_and_the_breaker_stays_closed() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: [(0.0, reply(cmd, 0x1103))]) as peer,
        session_for(peer, breaker_threshold=1) as s,
    ):
        done = Done()
        started(start_requests(s, reads(range(2)), done))
        responses, error = await done.outcome()
        assert responses is None and isinstance(error, EndCodeError)
        assert error.end_code.raw == 0x1103
        assert s.breaker_state is BreakerState.CLOSED
        assert s.stats.end_code_errors == 1
        assert_idle(s)


@on_virtual_time  # short timeouts, silent or late peer (uvloop: its clock cannot be virtual)
async def test_failures_open_the_breaker_and_then_it_declines() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: []) as peer,
        session_for(peer, retries=0, breaker_threshold=2, breaker_cooldown=(60, 60)) as s,
    ):
        for _ in range(2):
            done = Done()
            started(start_requests(s, reads(range(1)), done, timeout=0.05))
            _, error = await done.outcome()
            assert isinstance(error, FinsTimeout)
        assert s.breaker_state is BreakerState.OPEN
        assert start_requests(s, reads(range(1)), Done()) is None
        with pytest.raises(CircuitOpen):  # the awaitable path says why
            await s.request(0x01, 0x01, read_params(0))
        assert len(peer.received) == 2


@on_virtual_time  # counts transmissions: on the wall clock a loaded machine's late reply
# was sent again after the retransmission timeout (uvloop: its clock cannot be virtual)
async def test_an_answer_closes_a_breaker_that_counted_failures() -> None:
    replies = 0

    def second_answered(cmd: bytes) -> list[Reply]:
        nonlocal replies
        replies += 1
        return answer(cmd) if replies > 1 else []

    async with (
        on_asyncio_only(),
        udp_responder(second_answered) as peer,
        session_for(peer, retries=0, breaker_threshold=2) as s,
    ):
        done = Done()
        started(start_requests(s, reads(range(1)), done, timeout=0.05))
        assert isinstance((await done.outcome())[1], FinsTimeout)
        assert s._breaker.failures == 1
        done = Done()
        started(start_requests(s, reads(range(1)), done))
        assert (await done.outcome())[1] is None
        assert s._breaker.failures == 0 and len(peer.received) == 2


@on_virtual_time  # counts transmissions: on the wall clock a loaded machine's late reply
# was sent again after the retransmission timeout (uvloop: its clock cannot be virtual)
async def test_declines_without_a_free_slot_or_an_open_link() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: []) as peer,
        session_for(peer, max_in_flight=1) as s,
    ):
        first = started(start_requests(s, reads(range(1)), Done(), timeout=5))
        assert start_requests(s, reads(range(1)), Done()) is None  # the one slot is taken
        with anyio.fail_after(5):
            while not peer.received:
                await anyio.sleep(0.01)
        first.cancel()
        assert_idle(s)
        await s.aclose()
        assert start_requests(s, reads(range(1)), Done()) is None
        assert len(peer.received) == 1


async def test_cancel_quarantines_the_sids_and_never_calls_back() -> None:
    async with on_asyncio_only(), udp_responder(lambda cmd: []) as peer, session_for(peer) as s:
        done = Done()
        batch = started(start_requests(s, reads(range(3)), done, timeout=5))
        with anyio.fail_after(5):
            while len(peer.received) < 3:
                await anyio.sleep(0.01)
        batch.cancel()
        batch.cancel()  # (twice: nothing more)
        assert {key_of(cmd) for cmd in peer.received} <= set(s.sids.quarantine)
        assert s.stats.cancelled == 3
        assert_idle(s)
        await anyio.sleep(0.05)
        assert done.outcomes == []


async def test_a_link_lost_mid_request_fails_it() -> None:
    async with on_asyncio_only(), udp_responder(lambda cmd: []) as peer:
        s = session_for(peer)
        async with s:
            done = Done()
            started(start_requests(s, reads(range(2)), done, timeout=5))
            with anyio.fail_after(5):
                while len(peer.received) < 2:
                    await anyio.sleep(0.01)
            s.connection_lost(OSError("network is down"))
            responses, error = await done.outcome()
            assert responses is None and isinstance(error, ConnectionLost)
            assert "network is down" in str(error)
            assert_idle(s)


async def test_a_callback_that_raises_is_logged_not_raised_into_the_transport(
    caplog: pytest.LogCaptureFixture,
) -> None:
    def broken(responses: list[Response] | None, error: BaseException | None) -> None:
        raise RuntimeError("bug in the caller")

    async with on_asyncio_only(), udp_responder() as peer, session_for(peer) as s:
        with caplog.at_level(logging.ERROR, "aiofins.session"):
            started(start_requests(s, reads(range(1)), broken))
            with anyio.fail_after(5):
                while not caplog.records:
                    await anyio.sleep(0.01)
        assert "a request's callback failed" in caplog.records[0].getMessage()
        response = await s.request(0x01, 0x01, read_params(4))  # the session goes on
        assert response.data == expected(4)
        assert_idle(s)


async def test_start_requests_over_fins_tcp() -> None:
    from aiofins.protocol.header import FinsAddress
    from aiofins.simulator.plc import VirtualPLC
    from aiofins.simulator.runner import run_simulator
    from aiofins.transport.tcp import TcpTransport

    async with (
        on_asyncio_only(),
        run_simulator(VirtualPLC(), tcp=("127.0.0.1", 0)) as sim,
    ):
        transport = TcpTransport("127.0.0.1", sim.tcp_port)
        async with Session(transport, source=FinsAddress(0, 0, 0), dest=FinsAddress(0, 1, 0)) as s:
            await s.request(0x01, 0x02, read_params(10) + b"\x00\x2a")  # D10 = 42
            done = Done()
            started(start_requests(s, reads(range(10, 11)), done))
            responses, error = await done.outcome()
            assert error is None and responses is not None
            assert responses[0].data == b"\x00\x2a"
