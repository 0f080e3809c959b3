"""Session.request_many over real loopback UDP (asyncio fast path, trio fallback, uvloop)."""

from __future__ import annotations

import anyio
import pytest

from aiofins.protocol.errors import CommandError, FinsTimeout, ParameterError
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session

from ..virtual_time import on_virtual_time
from .test_session_udp import (
    PLC,
    Reply,
    answer,
    client_address,
    read_params,
    reply,
    session_for,
    udp_responder,
    word_data,
)


def reads(words: range) -> list[tuple[int, int, bytes]]:
    return [(0x01, 0x01, read_params(w)) for w in words]


def expected(word: int, node: int = PLC.node) -> bytes:
    return (((node << 12) ^ word) & 0xFFFF).to_bytes(2, "big")


def word_of(cmd: bytes) -> int:
    return int.from_bytes(cmd[13:15], "big")


def key_of(cmd: bytes) -> int:
    """The in-flight key of a command: DNA DA1 DA2 SID."""
    return (cmd[3] << 24) | (cmd[4] << 16) | (cmd[5] << 8) | cmd[9]


def assert_idle(session: Session) -> None:
    """Nothing of a batch left behind: no pending entry, every slot free."""
    assert session.stats.in_flight == 0
    assert all(state.slots.in_flight == 0 for state in session._dests.values())
    assert all(not state.slots.waiters for state in session._dests.values())


@pytest.mark.anyio
async def test_results_come_back_in_order_of_the_commands() -> None:
    held: list[bytes] = []
    most = 0

    def reverse_in_fours(cmd: bytes) -> list[Reply]:
        nonlocal most
        held.append(cmd)
        most = max(most, len(held))
        if len(held) < 4:
            return []
        batch = [(0.0, reply(c, 0, word_data(c))) for c in reversed(held)]
        held.clear()
        return batch

    async with udp_responder(reverse_in_fours) as peer, session_for(peer, max_in_flight=8) as s:
        results = await s.request_many(reads(range(200, 400)), window=4, timeout=5)
        assert [r.data for r in results] == [expected(w) for w in range(200, 400)]
        assert [word_of(c) for c in peer.received] == list(range(200, 400))
        assert most == 4  # never more than the window on the wire
        assert s.stats.completed == 200
        assert_idle(s)


@pytest.mark.anyio
async def test_window_is_capped_by_the_destinations_in_flight_limit() -> None:
    held: list[bytes] = []
    most = 0

    def pairs(cmd: bytes) -> list[Reply]:
        nonlocal most
        held.append(cmd)
        most = max(most, len(held))
        if len(held) < 3:
            return []
        out = [(0.0, reply(c, 0, word_data(c))) for c in held]
        held.clear()
        return out

    async with udp_responder(pairs) as peer, session_for(peer, max_in_flight=3) as s:
        results = await s.request_many(reads(range(30)), window=50, timeout=5)
        assert [r.data for r in results] == [expected(w) for w in range(30)]
        assert most == 3
        assert await s.request_many([]) == []
        with pytest.raises(CommandError):
            await s.request_many(reads(range(2)), window=0)
        with pytest.raises(CommandError):
            await s.request_many([(0x100, 0x01, b"")])


@pytest.mark.anyio
async def test_thousand_commands_with_reordered_duplicated_and_dropped_replies() -> None:
    """Replies come back reversed in batches; some twice, some long after their command was
    sent again, some never.

    Every result must be the data of its own command: a late reply or a duplicate must never
    complete another command. Each reply goes where an Ethernet unit sends it, to the port
    its source node last sent from: sent to the session's first socket, the replies to a
    second SID space (opened when SIDs linger long, as on a loaded machine) were lost and
    their commands timed out. A dropped command's late reply is timed from its
    retransmission, so every drop is retransmitted however slow the machine.
    """
    held: list[bytes] = []
    count = 0
    dropped: set[int] = set()
    #: dropped command (its frame, sent again unchanged) -> its reply, late
    late: dict[bytes, bytes] = {}

    def send(frame: bytes) -> None:  # to the port its destination node (our SA1) sent from
        peer.send(frame, peer.senders[frame[4]])

    async def send_later(delay: float, frame: bytes) -> None:
        await anyio.sleep(delay)
        send(frame)

    def chaos(cmd: bytes) -> list[Reply]:
        nonlocal count
        count += 1
        word = word_of(cmd)
        if count % 41 == 0 and word not in dropped:
            dropped.add(word)  # lost: answered long after it is sent again, or never
            if count % 2:
                late[cmd] = reply(cmd, 0, word_data(cmd))
            return []
        if cmd in late:  # sent again: its first reply comes 0.4 s later, to a lingering SID
            peer.tg.start_soon(send_later, 0.4, late.pop(cmd))
        held.append(cmd)
        if len(held) < 6:
            return []
        for c in reversed(held):
            send(reply(c, 0, word_data(c)))
        for c in held[::5]:  # duplicates
            send(reply(c, 0, word_data(c)))
        held.clear()
        return []

    async def flush_stragglers() -> None:
        while True:
            await anyio.sleep(0.01)
            cmds = list(held)
            held.clear()
            for c in cmds:
                send(reply(c, 0, word_data(c)))

    # timeout bounds a whole command (its 4 transmissions); generous for a loaded machine:
    # that none timed out and every drop was sent again is asserted on the counts
    options = {"max_in_flight": 50, "timeout": 5.0, "quarantine_factor": 4.0}
    async with udp_responder(chaos) as peer, session_for(peer, **options) as s:
        peer.tg.start_soon(flush_stragglers)
        nodes = [FinsAddress(0, n, 0) for n in (1, 2)]
        for node in nodes:
            results = await s.request_many(
                reads(range(1000)), dest=node, idempotent=True, retries=3
            )
            assert [r.data for r in results] == [expected(w, node.node) for w in range(1000)]
        assert dropped
        # Every drop was retransmitted (same SID) and no command timed out.
        assert s.stats.timeouts == 0 and s.stats.retries >= len(dropped)
        assert s.stats.completed == 2000
        assert s.stats.duplicates > 0
        assert_idle(s)


@pytest.mark.anyio
async def test_timeout_raises_fins_timeout_and_quarantines_every_sid() -> None:
    async with (
        udp_responder(lambda cmd: []) as peer,
        session_for(peer, max_in_flight=3, quarantine_factor=50.0) as s,
    ):
        # (timeouts long enough for every transmission to go out first on a loaded machine)
        with pytest.raises(FinsTimeout) as info:
            await s.request_many(reads(range(5)), timeout=0.5)
        assert "no response to command 0101" in str(info.value)
        assert len(peer.received) == 3  # the first error stops the batch
        assert {key_of(c) for c in peer.received} <= set(s._quarantine)
        assert s.stats.timeouts >= 1
        assert_idle(s)
        # Idempotent commands are retransmitted (same frame, same SID) before giving up.
        peer.received.clear()
        with pytest.raises(FinsTimeout) as info:
            await s.request_many(reads(range(1)), timeout=0.7, idempotent=True, retries=2)
        assert "in 3 attempts within 0.7 s" in str(info.value)
        assert len(peer.received) == 3 and len(set(peer.received)) == 1
        assert_idle(s)


@pytest.mark.anyio
async def test_end_code_error_is_raised_and_the_rest_abandoned() -> None:
    seven: list[bytes] = []

    def bad_word_7(cmd: bytes) -> list[Reply]:
        word = word_of(cmd)
        if word == 7:
            seven.append(cmd)  # failed once 8, 9 and 10 are on the wire
            return []
        if word == 10:
            return [(0.0, reply(seven[0], 0x1101))]
        if word > 7:
            return []  # never answered: abandoned when word 7 fails
        return answer(cmd)

    async with (
        udp_responder(bad_word_7) as peer,
        session_for(peer, max_in_flight=4, quarantine_factor=50.0) as s,
    ):
        with pytest.raises(ParameterError) as info:
            await s.request_many(reads(range(20)), timeout=5)
        assert info.value.code == 0x1101 and info.value.command_code == 0x0101
        assert s.stats.end_code_errors == 1
        unanswered = {key_of(c) for c in peer.received if word_of(c) > 7}
        assert unanswered and unanswered <= set(s._quarantine)
        assert_idle(s)
        peer.handler = answer
        results = await s.request_many(reads(range(100, 110)))
        assert [r.data for r in results] == [expected(w) for w in range(100, 110)]


@pytest.mark.anyio
async def test_busy_end_codes_are_retried_with_a_fresh_sid() -> None:
    busy_words: dict[int, int] = {}

    def busy_twice(cmd: bytes) -> list[Reply]:
        word = word_of(cmd)
        if word % 3 == 0 and busy_words.get(word, 0) < 2:
            busy_words[word] = busy_words.get(word, 0) + 1
            return [(0.0, reply(cmd, 0x2604))]
        return answer(cmd)

    async with udp_responder(busy_twice) as peer, session_for(peer, busy_backoff=0.001) as s:
        results = await s.request_many(reads(range(12)))
        assert [r.data for r in results] == [expected(w) for w in range(12)]
        assert s.stats.busy_retries == 8
        sids = [c[9] for c in peer.received if word_of(c) == 3]
        assert len(sids) == 3 and len(set(sids)) == 3
        assert_idle(s)


@pytest.mark.anyio
async def test_cancellation_frees_slots_and_quarantines_sids() -> None:
    arrived = anyio.Event()

    def hold(cmd: bytes) -> list[Reply]:
        if len(peer.received) == 4:
            arrived.set()
        return []

    async with (
        udp_responder(hold) as peer,
        session_for(peer, max_in_flight=4, quarantine_factor=50.0) as s,
    ):
        async with anyio.create_task_group() as tg:
            tg.start_soon(s.request_many, reads(range(10)))
            await arrived.wait()
            tg.cancel_scope.cancel()
        held = list(peer.received)
        assert len(held) == 4
        assert {key_of(c) for c in held} <= set(s._quarantine)
        assert s.stats.cancelled == 4
        assert_idle(s)
        # Their replies come late now: counted, never delivered to the next batch.
        addr = client_address(s)
        for c in held:
            peer.send(reply(c, 0, b"\xde\xad"), addr)
        peer.handler = answer
        results = await s.request_many(reads(range(50, 60)))
        assert [r.data for r in results] == [expected(w) for w in range(50, 60)]
        assert s.stats.late_replies == 4
        assert_idle(s)


@pytest.mark.anyio
async def test_other_callers_share_the_destinations_slots_with_a_batch() -> None:
    async with udp_responder() as peer, session_for(peer, max_in_flight=4) as s:
        singles: dict[int, bytes] = {}

        async def single(word: int) -> None:
            singles[word] = (await s.request(0x01, 0x01, read_params(word), timeout=5)).data

        async with anyio.create_task_group() as tg:
            for word in range(1000, 1020):
                tg.start_soon(single, word)
            results = await s.request_many(reads(range(300)), timeout=5)
        assert [r.data for r in results] == [expected(w) for w in range(300)]
        assert singles == {w: expected(w) for w in range(1000, 1020)}
        assert_idle(s)


@pytest.mark.anyio
async def test_on_response_reports_each_reply_once_as_it_arrives() -> None:
    held: list[bytes] = []

    def reverse_in_fours(cmd: bytes) -> list[Reply]:
        held.append(cmd)
        if len(held) < 4:
            return []
        batch = [(0.0, reply(c, 0, word_data(c))) for c in reversed(held)]
        held.clear()
        return batch

    seen: list[tuple[int, bytes]] = []
    async with udp_responder(reverse_in_fours) as peer, session_for(peer, max_in_flight=4) as s:
        results = await s.request_many(
            reads(range(500, 540)),
            timeout=5,
            on_response=lambda i, r: seen.append((i, r.data)),
        )
        assert [r.data for r in results] == [expected(w) for w in range(500, 540)]
        assert sorted(seen) == [(i, expected(500 + i)) for i in range(40)]
        if s.on_asyncio:  # the receive callback reports in arrival order: last of four first
            assert [i for i, _ in seen] == [4 * g + k for g in range(10) for k in (3, 2, 1, 0)]
        assert_idle(s)


@pytest.mark.anyio
async def test_an_exception_in_on_response_ends_the_batch_and_is_raised() -> None:
    calls: list[int] = []

    def stop_at_third(index: int, _response: object) -> None:
        calls.append(index)
        if len(calls) == 3:
            raise RuntimeError("the caller's callback failed")

    async with (
        udp_responder() as peer,
        session_for(peer, max_in_flight=4, quarantine_factor=50.0) as s,
    ):
        with pytest.raises(RuntimeError, match="callback failed"):
            await s.request_many(reads(range(30)), timeout=5, on_response=stop_at_third)
        assert len(calls) == 3  # nothing reported after the failure
        assert len(peer.received) < 30  # the rest was not sent
        assert_idle(s)
        results = await s.request_many(reads(range(60, 70)))
        assert [r.data for r in results] == [expected(w) for w in range(60, 70)]
        assert_idle(s)


@pytest.mark.anyio
async def test_on_frame_hands_each_normal_reply_frame_and_returns_no_responses() -> None:
    """``on_frame(index, frame)``: each command's normal reply frame itself, once, in
    arrival order (flags 0040 included: a normal completion); a busy reply is sent again
    and only its normal reply handed; nothing is returned (no Response is made)."""
    held: list[bytes] = []
    busy: set[int] = set()

    def reverse_in_fours(cmd: bytes) -> list[Reply]:
        word = word_of(cmd)
        if word == 705 and word not in busy:  # busy once: sent again, a fresh SID
            busy.add(word)
            return [(0.0, reply(cmd, 0x2604))]
        held.append(cmd)
        if len(held) < 4:
            return []
        out = [(0.0, reply(c, 0x0040 if word_of(c) == 702 else 0, word_data(c)))
               for c in reversed(held)]  # fmt: skip
        held.clear()
        return out

    frames: list[tuple[int, bytes]] = []
    async with (
        udp_responder(reverse_in_fours) as peer,
        session_for(peer, max_in_flight=4, busy_backoff=0.001) as s,
    ):
        results = await s.request_many(
            reads(range(700, 740)),
            timeout=5,
            idempotent=True,
            retries=0,  # (none sent again on a loaded machine: the counts below are exact)
            on_frame=lambda i, frame: frames.append((i, frame)),
        )
        assert results == []
        assert sorted(i for i, _ in frames) == list(range(40))
        for i, frame in frames:
            assert frame[14:] == expected(700 + i)
            assert frame[9] == next(c for c in reversed(peer.received) if word_of(c) == 700 + i)[9]
            assert frame[12:14] == (b"\x00\x40" if i == 2 else b"\x00\x00")
        assert s.stats.completed == 40 and s.stats.busy_retries == 1
        assert [word_of(c) for c in peer.received].count(705) == 2
        if s.on_asyncio:  # the receive callback hands them over in arrival order
            assert [i for i, _ in frames][:4] == [3, 2, 1, 0]
        assert_idle(s)


@pytest.mark.anyio
async def test_an_exception_in_on_frame_ends_the_batch_and_is_raised() -> None:
    calls: list[int] = []

    def stop_at_third(index: int, _frame: bytes) -> None:
        calls.append(index)
        if len(calls) == 3:
            raise RuntimeError("the caller's decoder failed")

    async with (
        udp_responder() as peer,
        session_for(peer, max_in_flight=4, quarantine_factor=50.0) as s,
    ):
        with pytest.raises(RuntimeError, match="decoder failed"):
            await s.request_many(reads(range(30)), timeout=5, on_frame=stop_at_third)
        assert len(calls) == 3  # nothing handed over after the failure
        assert len(peer.received) < 30  # the rest was not sent
        assert_idle(s)
        with pytest.raises(ParameterError):  # an end code error ends it the same way
            peer.handler = lambda cmd: [(0.0, reply(cmd, 0x1103))]
            await s.request_many(reads(range(5)), timeout=5, on_frame=stop_at_third)
        assert len(calls) == 3
        assert_idle(s)


@on_virtual_time
async def test_a_burst_short_of_sids_sends_those_with_one_and_the_rest_as_sids_come_free() -> None:
    """A burst of a batch meets the destination's SIDs nearly all quarantined (a batch
    timed out): the commands that find a SID go out together, each on its own free SID;
    the others wait for one (counted) and go out as the quarantine ends; every result is
    its own command's."""
    async with (
        udp_responder(lambda cmd: []) as peer,
        session_for(peer, max_in_flight=200, max_sid_spaces=1, min_quarantine=1.0) as s,
    ):
        with pytest.raises(FinsTimeout):
            await s.request_many(reads(range(200)), timeout=0.2)
        quarantined = set(s._quarantine)
        assert len(quarantined) == 200 and len(peer.received) == 200
        peer.received.clear()
        peer.handler = answer
        results = await s.request_many(reads(range(1000, 1200)), timeout=5)
        assert [r.data for r in results] == [expected(w) for w in range(1000, 1200)]
        sent = [c for c in peer.received if word_of(c) >= 1000]  # (not the 1st batch's last)
        assert sorted(word_of(c) for c in sent) == list(range(1000, 1200))
        assert not {key_of(c) for c in sent} & quarantined
        if s.on_asyncio:  # one burst: those with a SID first, in order
            assert [word_of(c) for c in sent[:56]] == list(range(1000, 1056))
        assert s.stats.sid_exhausted > 0 and s.stats.completed == 200
        assert_idle(s)


@pytest.mark.anyio
async def test_the_answered_commands_of_a_batch_leave_the_deadlines_by_the_next_burst() -> None:
    """A batch's replies leave the deadline structure's upkeep to its next burst (once per
    burst, not per reply): answered requests in it stay within what one burst answers
    (twice the window with those in flight), and none is left when the batch is done."""
    window = 8
    most = 0

    def kept(_index: int, _frame: bytes) -> None:
        nonlocal most
        most = max(most, len(s._fifo) + len(s._heap))

    async with udp_responder() as peer, session_for(peer, max_in_flight=window) as s:
        await s.request_many(reads(range(500)), timeout=5, on_frame=kept)
        assert 0 < most <= 2 * window
        assert not s._fifo and not s._heap
        assert s.stats.completed == 500
        assert_idle(s)
