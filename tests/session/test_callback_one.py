"""start_request: one command whose reply frame goes to a callback (the Poller's scan of one
frame), over real loopback UDP (asyncio and uvloop; under trio it declines)."""

from __future__ import annotations

import logging

import anyio
import pytest

from aiofins.protocol.errors import ConnectionLost, EndCodeError, FinsTimeout
from aiofins.session.breaker import BreakerState
from aiofins.session.callback import CallbackPending, start_request

from ..virtual_time import on_virtual_time
from .test_callback import on_asyncio_only
from .test_request_many import assert_idle, expected, key_of, reads
from .test_session_udp import Reply, answer, read_params, reply, session_for, udp_responder

pytestmark = pytest.mark.anyio

Outcome = tuple[bytes | None, BaseException | None]


class Done:
    """The callback: records each outcome and wakes the test."""

    def __init__(self) -> None:
        self.outcomes: list[Outcome] = []
        self.event = anyio.Event()

    def __call__(self, frame: bytes | None, error: BaseException | None) -> None:
        self.outcomes.append((frame, error))
        self.event.set()

    async def outcome(self) -> Outcome:
        await self.event.wait()
        assert len(self.outcomes) == 1
        return self.outcomes[0]


def started(request: CallbackPending | None) -> CallbackPending:
    assert request is not None, "start_request declined"
    return request


ONE = reads(range(100, 101))[0]


async def test_the_reply_frame_comes_to_the_callback() -> None:
    async with on_asyncio_only(), udp_responder() as peer, session_for(peer) as s:
        done = Done()
        started(start_request(s, ONE, done))
        assert done.outcomes == []  # never from inside start_request
        frame, error = await done.outcome()
        assert error is None and frame is not None
        assert frame[14:] == expected(100) and frame[9] == peer.received[0][9]
        assert [cmd[10:] for cmd in peer.received] == [b"\x01\x01" + read_params(100)]
        assert s.stats.completed == 1
        assert_idle(s)


async def test_trio_declines() -> None:
    from aiofins.transport.base import is_asyncio

    if is_asyncio():
        pytest.skip("trio only")
    async with udp_responder() as peer, session_for(peer) as s:
        assert start_request(s, ONE, Done()) is None
        assert peer.received == []


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
        started(start_request(s, ONE, done, timeout=2.0))
        frame, error = await done.outcome()
        assert error is None and frame is not None and frame[14:] == expected(100)
        assert len(peer.received) == 2 and peer.received[0] == peer.received[1]
        assert s.stats.retries == 1
        assert_idle(s)


async def test_no_reply_fails_as_a_timeout_and_quarantines_the_sid() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: []) as peer,
        session_for(peer, retries=1) as s,
    ):
        done = Done()
        started(start_request(s, ONE, done, timeout=0.2))
        frame, error = await done.outcome()
        assert frame is None and isinstance(error, FinsTimeout)
        assert "no response to command 0101" in str(error) and "in 2 attempts" in str(error)
        assert len(peer.received) == 2
        assert key_of(peer.received[0]) in s.sids.quarantine
        assert s.stats.timeouts == 1
        assert s._breaker.failures == 1
        assert_idle(s)


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
        started(start_request(s, ONE, done))
        frame, error = await done.outcome()
        assert error is None and frame is not None and frame[14:] == expected(100)
        assert s.stats.busy_retries == 2 and s.stats.completed == 1
        assert len({cmd[9] for cmd in peer.received}) == 3
        assert_idle(s)


@on_virtual_time  # counts transmissions: on the wall clock a loaded machine's late reply
# was sent again after the retransmission timeout (uvloop: its clock cannot be virtual)
async def test_busy_too_often_fails_with_the_end_code() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: [(0.0, reply(cmd, 0x2605))]) as peer,
        session_for(peer, busy_backoff=0.001, busy_retries=2) as s,
    ):
        done = Done()
        started(start_request(s, ONE, done))
        frame, error = await done.outcome()
        assert frame is None and isinstance(error, EndCodeError)
        assert error.end_code.raw == 0x2605
        assert len(peer.received) == 3 and s.stats.busy_retries == 2
        assert_idle(s)


async def test_an_end_code_fails_with_its_error_and_the_breaker_stays_closed() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: [(0.0, reply(cmd, 0x1103))]) as peer,
        session_for(peer, breaker_threshold=1) as s,
    ):
        done = Done()
        started(start_request(s, ONE, done))
        frame, error = await done.outcome()
        assert frame is None and isinstance(error, EndCodeError)
        assert error.end_code.raw == 0x1103
        assert s.breaker_state is BreakerState.CLOSED
        assert s.stats.end_code_errors == 1
        assert_idle(s)


async def test_cpu_error_flags_complete_the_request_and_are_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: [(0.0, reply(cmd, 0x0040, b"\x00\x07"))]) as peer,
        session_for(peer) as s,
    ):
        done = Done()
        with caplog.at_level(logging.WARNING, "aiofins"):
            started(start_request(s, ONE, done))
            frame, error = await done.outcome()
        assert error is None and frame is not None and frame[12:] == b"\x00\x40\x00\x07"
        assert s.stats.completed == 1
        assert any("non-fatal" in r.getMessage().lower() for r in caplog.records)
        assert_idle(s)


async def test_declines_without_a_free_slot_or_an_open_link() -> None:
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: []) as peer,
        session_for(peer, max_in_flight=1) as s,
    ):
        first = started(start_request(s, ONE, Done(), timeout=5))
        assert start_request(s, ONE, Done()) is None  # the one slot is taken
        first.cancel()
        assert_idle(s)
        await s.aclose()
        assert start_request(s, ONE, Done()) is None


async def test_cancel_quarantines_the_sid_and_never_calls_back() -> None:
    async with on_asyncio_only(), udp_responder(lambda cmd: []) as peer, session_for(peer) as s:
        done = Done()
        request = started(start_request(s, ONE, done, timeout=5))
        request.cancel()
        request.cancel()  # (twice: nothing more)
        assert request.key in s.sids.quarantine
        assert s.stats.cancelled == 1
        assert_idle(s)
        assert done.outcomes == []


async def test_cancel_while_busy_gives_everything_back() -> None:
    """On every loop (its first wait, 120/7 s, is far above a loaded machine's reply)."""
    async with (
        on_asyncio_only(),
        udp_responder(lambda cmd: [(0.0, reply(cmd, 0x2604))]) as peer,
        session_for(peer, busy_backoff=60.0) as s,
    ):
        # (the 60 s pause fits in the call's time: the session retries only then)
        request = started(start_request(s, ONE, Done(), timeout=120))
        while not s.stats.busy_retries:  # (the reply comes on the loop's next passes)
            await anyio.lowlevel.checkpoint()
        assert request.handle is not None
        request.cancel()
        assert_idle(s)
        assert len(peer.received) == 1


async def test_a_link_lost_mid_request_fails_it() -> None:
    async with on_asyncio_only(), udp_responder(lambda cmd: []) as peer:
        s = session_for(peer)
        async with s:
            done = Done()
            started(start_request(s, ONE, done, timeout=5))
            s.connection_lost(OSError("network is down"))
            frame, error = await done.outcome()
            assert frame is None and isinstance(error, ConnectionLost)
            assert "network is down" in str(error)
            assert_idle(s)


async def test_a_callback_that_raises_is_logged_not_raised_into_the_transport(
    caplog: pytest.LogCaptureFixture,
) -> None:
    failed = anyio.Event()

    def broken(frame: bytes | None, error: BaseException | None) -> None:
        failed.set()
        raise RuntimeError("bug in the caller")

    async with on_asyncio_only(), udp_responder() as peer, session_for(peer) as s:
        with caplog.at_level(logging.ERROR, "aiofins.session"):
            started(start_request(s, ONE, broken))
            await failed.wait()
        assert "a request's callback failed" in caplog.records[0].getMessage()
        response = await s.request(0x01, 0x01, read_params(4))  # the session goes on
        assert response.data == expected(4)
        assert_idle(s)
