"""Duplicates of replies and SID reuse (issue #22): what counts as a duplicate, and how a
copy of an old reply is told apart from a new reply after the SID was reused. On virtual
time (trio's MockClock, asyncio on looptime): every count is exact."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import pytest

from aiofins.memnet import Fate, MemoryNetwork, Packet
from aiofins.protocol.errors import FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.session.sids import LINGER_FLOOR
from aiofins.simulator import VirtualPLC
from aiofins.transport import MemoryTransport, UdpTransport

from ..virtual_time import on_virtual_time
from .test_session_lifecycle import expected
from .test_session_udp import (
    Handler,
    Reply,
    read_params,
    reply,
    session_for,
    udp_responder,
    word_data,
)

#: The peer's address on the in-memory network (see :func:`memnet_plc`).
PEER = ("10.0.0.10", 9600)


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


def copies_of_the_first_reply(
    late: float, rtt_of_256: float, same_data: bool = False, taught: float = 0.0
) -> Handler:
    """A peer whose first reply (word 0, SID 0) the network copies ``late`` s later; the
    reply to the 257th read (word 256, SID 0 again) comes ``rtt_of_256`` s after it; with
    ``same_data`` it holds word 0's data, and its retransmissions are answered at once
    (else not at all). With ``taught``, the second reply (word 1) is copied that late.
    """
    seen: set[bytes] = set()

    def handler(cmd: bytes) -> list[Reply]:
        word = int.from_bytes(cmd[13:15], "big")
        data = word_data(cmd)
        if word == 0:
            good = reply(cmd, 0, data)
            return [(0.0, good), (late, good)]
        if word == 1 and taught:  # an early duplicate: the link duplicates replies
            good = reply(cmd, 0, data)
            return [(0.0, good), (taught, good)]
        if word == 256:
            if same_data:
                data = word_data(cmd[:13] + b"\x00\x00" + cmd[15:])
            if cmd in seen:  # a retransmission: answered at once if the data is the same
                return [(0.0, reply(cmd, 0, data))] if same_data else []
            seen.add(cmd)
            return [(rtt_of_256, reply(cmd, 0, data))]
        return [(0.0, reply(cmd, 0, data))]

    return handler


@on_virtual_time
async def test_a_copy_of_a_sid_s_old_reply_never_answers_the_request_that_reused_it() -> None:
    """Issue #22, defect 5: the link has shown a duplicate 0.15 s late (the SIDs linger
    0.3 s); the first reply's copy comes 0.5 s late, after SID 0 was reused for the read of
    word 256, whose reply takes 0.6 s: the copy comes first. It is byte for byte the reply
    the SID was last answered with, to a request that asked something else, within twice
    the linger: held back, and the read's own reply answers it (the copy then teaches the
    linger: 1 s)."""
    async with (
        udp_responder(copies_of_the_first_reply(0.5, 0.6, taught=0.15)) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0) as session,
    ):
        for word in range(257):
            if word == 2:
                await anyio.sleep(0.2)  # the duplicate of word 1's reply comes
                assert session.sids.linger == pytest.approx(0.3)
            r = await session.request(0x01, 0x01, read_params(word), idempotent=True)
            assert r.data == expected(word), word
        assert peer.received[256][9] == peer.received[0][9] == 0  # SID 0 again
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.unsolicited) == (257, 2, 0)
        assert session.sids.linger == pytest.approx(1.0)


@on_virtual_time
async def test_a_new_reply_the_same_bytes_as_the_sid_s_last_answers_after_a_resend() -> None:
    """The read of word 256 under SID 0 gets, at once, the same bytes as SID 0's last reply
    (word 0's data; as if both words held the same value). Nothing tells it from a late
    copy (a linger of 0.05 s: a duplicate may come): held back, and the read sent again
    at once (same frame and SID); the reply to that answers it, without waiting for a
    retransmission timeout. No linger learnt."""
    async with (
        udp_responder(copies_of_the_first_reply(9.0, 0.0, same_data=True)) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, min_linger=0.05) as session,
    ):
        for word in range(256):
            await session.request(0x01, 0x01, read_params(word), idempotent=True)
        start = anyio.current_time()
        r = await session.request(0x01, 0x01, read_params(256), idempotent=True)
        assert r.data == expected(0)
        assert [c for c in peer.received if c[13:15] == b"\x01\x00"] == [peer.received[256]] * 2
        # (SID 0 free after its linger, 0.05 s; sent again at once where the transport
        # sends synchronously, else at the first retransmission timeout)
        assert anyio.current_time() - start <= 0.05 + session.rto_bounds[0] + 1e-9
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.retries) == (257, 1, 1)
        assert session.sids.linger == 0.05


@on_virtual_time
async def test_the_same_question_under_a_reused_sid_is_answered_at_once() -> None:
    """512 reads of one word (the same frame under each SID the second time round, the
    same reply): a poll of values that did not change is not held back."""
    async with (
        udp_responder() as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, min_linger=0.001) as session,
    ):
        for _ in range(512):
            r = await session.request(0x01, 0x01, read_params(7), idempotent=True)
            assert r.data == expected(7)
        assert len(peer.received) == 512
        assert (session.stats.completed, session.stats.duplicates) == (512, 0)


@on_virtual_time
async def test_a_read_without_retries_is_not_answered_by_a_copy_of_its_sid_s_old_reply() -> None:
    """The same as above with ``retries=0`` (the soak's seeds 40079 and 30485: reads that
    could not be sent again took a copy of their SID's last reply, another read's words).
    A read is idempotent: on a link that has shown duplicates it keeps its frame though it
    has no retries, the copy is held back, the read sent once more (where the transport
    sends synchronously; else it just waits on), and its own reply answers it. No
    timeout, no other retransmission."""
    async with (
        udp_responder(copies_of_the_first_reply(0.5, 0.6, taught=0.15)) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        for word in range(257):
            if word == 2:
                await anyio.sleep(0.2)  # the duplicate of word 1's reply comes
                assert session.sids.linger == pytest.approx(0.3)
            r = await session.request(0x01, 0x01, read_params(word), idempotent=True)
            assert r.data == expected(word), word
        assert peer.received[256][9] == peer.received[0][9] == 0  # SID 0 again
        again = int(session.transport.fast_send is not None)
        resent = [c for c in peer.received if c[13:15] == b"\x01\x00"]
        assert resent == [peer.received[256]] * (1 + again)  # same frame and SID
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.unsolicited) == (257, 2, 0)
        assert (stats.retries, stats.timeouts) == (again, 0)
        assert session.sids.linger == pytest.approx(1.0)


def copies_of_the_first_reply_two_uses_later(late: float, rtt_of_512: float) -> Handler:
    """A peer whose first reply (word 0, SID 0) the network copies ``late`` s later, whose
    second reply (word 1) it copies 0.15 s later (the link duplicates replies), and whose
    reply to the 513th read (word 512: SID 0's third use) comes ``rtt_of_512`` s after it
    (its retransmissions: at once). Every other read is answered at once."""
    seen: set[bytes] = set()

    def handler(cmd: bytes) -> list[Reply]:
        word = int.from_bytes(cmd[13:15], "big")
        good = reply(cmd, 0, word_data(cmd))
        if word == 0:
            return [(0.0, good), (late, good)]
        if word == 1:
            return [(0.0, good), (0.15, good)]
        if word == 512 and cmd not in seen:
            seen.add(cmd)
            return [(rtt_of_512, good)]
        return [(0.0, good)]

    return handler


@on_virtual_time
async def test_a_copy_of_a_reply_the_sid_carried_two_uses_earlier_is_held_back() -> None:
    """Issue #22, defect 5 (the soak's seed 30485): the copy of SID 0's first reply (word
    0) comes 0.7 s late, when SID 0 carries its third request (word 512), whose own reply
    takes 0.3 s: the copy comes first. It is not the SID's last reply (word 256's) but a
    byte-for-byte copy of an earlier one, within the hold window on a link that has shown
    duplicates: held back like a copy of the last, and the read's own reply answers it
    (the copy then teaches the linger from the reply it copies: 1.4 s)."""
    async with read_513_words(copies_of_the_first_reply_two_uses_later(0.7, 0.3)) as (
        session,
        sent_512,
    ):
        again = int(session.transport.fast_send is not None)
        assert sent_512 == 1 + again  # same frame and SID
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.unsolicited) == (513, 2, 0)
        assert (stats.retries, stats.timeouts) == (again, 0)
        assert session.sids.linger == pytest.approx(1.4)


@asynccontextmanager
async def read_513_words(handler: Handler) -> AsyncIterator[tuple[Session, int]]:
    """Words 0 to 512 read one by one from ``handler``'s peer through one SID space,
    ``retries=0`` (SID 0 carries words 0, 256 and 512), each checked, after the link
    showed a duplicate 0.15 s late (word 1's: a linger of 0.3 s): the session, and how
    many times the read of word 512 was sent (same frame and SID each time)."""
    async with (
        udp_responder(handler) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        for word in range(513):
            if word == 2:
                await anyio.sleep(0.2)  # the duplicate of word 1's reply comes
                assert session.sids.linger == pytest.approx(0.3)
            r = await session.request(0x01, 0x01, read_params(word), idempotent=True)
            assert r.data == expected(word), word
        assert peer.received[512][9] == peer.received[256][9] == peer.received[0][9] == 0
        sent = [c for c in peer.received if c[13:15] == b"\x02\x00"]
        assert set(sent) == {peer.received[512]}
        yield session, len(sent)


def copies_of_the_sid_s_last_two_replies_first() -> Handler:
    """A peer whose reply to word 1 the network copies 0.15 s later (the link duplicates
    replies) and whose reply to the read of word 512 (SID 0's third use) comes 0.6 s
    after it, after copies of SID 0's two earlier replies (word 0's, then word 256's:
    0.01 and 0.02 s after the read's command); that read sent again is never answered
    (lost). Every other read is answered at once."""
    replies: dict[int, bytes] = {}
    seen: set[bytes] = set()

    def handler(cmd: bytes) -> list[Reply]:
        word = int.from_bytes(cmd[13:15], "big")
        good = reply(cmd, 0, word_data(cmd))
        replies[word] = good
        if word == 1:
            return [(0.0, good), (0.15, good)]
        if word == 512:
            if cmd in seen:
                return []
            seen.add(cmd)
            return [(0.01, replies[0]), (0.02, replies[256]), (0.6, good)]
        return [(0.0, good)]

    return handler


@on_virtual_time
async def test_copies_of_the_sid_s_last_two_replies_before_its_own_are_both_held_back() -> None:
    """Issue #22, defect 5 (the soak's seed 220447): SID 0's third request (word 512)
    gets a copy of the SID's first reply (word 0's), then one of its last (word 256's),
    both before its own reply: each is held back (the second is another reply's copy,
    not the bytes held before), and the read's own reply answers it; the latest copy
    teaches the linger. Before, the second copy answered it: word 256's words."""
    async with read_513_words(copies_of_the_sid_s_last_two_replies_first()) as (
        session,
        sent_512,
    ):
        again = int(session.transport.fast_send is not None)
        assert sent_512 == 1 + 2 * again  # each hold: sent again
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.unsolicited) == (513, 3, 0)
        assert (stats.retries, stats.timeouts) == (2 * again, 0)
        # (word 0's reply came at 0 s, its copy at 0.51 s: the latest of the two, taught)
        assert session.sids.linger == pytest.approx(1.02)


def a_copy_of_an_older_reply(late: float, taught_by: int = -1) -> Handler:
    """A peer whose first reply (word 0, SID 0) the network copies ``late`` s later; with
    ``taught_by``, that word's reply is copied 0.15 s later too (the link's first duplicate
    the session can see at once); the read of word 512 (SID 0's third use) is answered 0.6 s
    after it is first sent, its retransmissions at once. Every other read at once."""
    seen: set[bytes] = set()

    def handler(cmd: bytes) -> list[Reply]:
        word = int.from_bytes(cmd[13:15], "big")
        good = reply(cmd, 0, word_data(cmd))
        if word == 0:
            return [(0.0, good), (late, good)]
        if word == taught_by:
            return [(0.0, good), (0.15, good)]
        if word == 512 and cmd not in seen:
            seen.add(cmd)
            return [(0.6, good)]
        return [(0.0, good)]

    return handler


@on_virtual_time
async def test_the_link_s_first_duplicate_may_copy_a_reply_older_than_its_sid_s_last() -> None:
    """Issue #22, defect 5 (soak seeds 43005 and 43015): at a high rate a SID comes round
    before the copy of its reply does, so the first copy a link shows is most often of a
    reply older than its SID's last. It is a duplicate all the same (the space keeps its
    recent replies on every link, :attr:`SidSpace.heard`), and teaches the linger from the
    reply it copies: 2 x 0.3 s. (Before: unsolicited, and the link never learnt a linger.)"""
    async with (
        udp_responder(a_copy_of_an_older_reply(0.3)) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0) as session,
    ):
        for word in range(300):
            r = await session.request(0x01, 0x01, read_params(word), idempotent=True)
            assert r.data == expected(word), word
        assert peer.received[256][9] == 0  # SID 0 again: its last reply is word 256's
        await anyio.sleep(0.5)  # word 0's copy comes
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.unsolicited) == (300, 1, 0)
        assert session.sids.linger == pytest.approx(0.6)


@on_virtual_time
async def test_a_copy_of_a_reply_heard_before_the_link_s_first_duplicate_is_held_back() -> None:
    """Issue #22, defect 5 (soak seed 30485): word 0's reply (SID 0) is copied 0.7 s late;
    SID 0 carries word 256 at once, the link shows its first duplicate (word 300's, 0.15 s
    late) after that, and SID 0's third request (word 512, its reply 0.6 s late) is on its
    way when the copy of word 0's comes. The replies heard before the first duplicate start
    each SID's history then (not only its last reply, word 256's): the copy is held back,
    the read sent once more, and its own reply answers it (before: word 0's data)."""
    async with (
        udp_responder(a_copy_of_an_older_reply(0.7, taught_by=300)) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        for word in range(513):
            if word == 301:
                await anyio.sleep(0.35)  # word 300's copy comes, SID 0's linger ends
                assert session.sids.linger == pytest.approx(0.3)
            r = await session.request(0x01, 0x01, read_params(word), idempotent=True)
            assert r.data == expected(word), word
        assert peer.received[512][9] == peer.received[256][9] == peer.received[0][9] == 0
        again = int(session.transport.fast_send is not None)
        resent = [c for c in peer.received if c[13:15] == b"\x02\x00"]
        assert resent == [peer.received[512]] * (1 + again)  # same frame and SID
        stats = session.stats
        assert (stats.completed, stats.unsolicited) == (513, 0)
        assert (stats.retries, stats.timeouts) == (again, 0)
        assert session.sids.linger == pytest.approx(1.4)


@on_virtual_time
async def test_a_read_not_marked_idempotent_is_sent_again_rather_than_take_a_copy() -> None:
    """Issue #22, defect 5 (soak seeds 30117 and 43004: ``execute_many`` of reads, not
    marked idempotent, without retries): a read changes nothing in the PLC, so on a link
    that has shown duplicates the duplicate rule may send it once more whatever the caller
    said. The copy of SID 0's first reply comes to the read of word 256 (a batch of two
    reads): held back, the read sent again, its own reply answers it (before: word 0's
    data). Nothing else is sent twice."""
    async with (
        udp_responder(copies_of_the_first_reply(0.5, 0.6, taught=0.15)) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        for word in range(256):
            if word == 2:
                await anyio.sleep(0.2)  # the duplicate of word 1's reply comes
                assert session.sids.linger == pytest.approx(0.3)
            r = await session.request(0x01, 0x01, read_params(word))
            assert r.data == expected(word), word
        both = [(0x01, 0x01, read_params(256)), (0x01, 0x01, read_params(257))]
        responses = await session.request_many(both)
        assert [r.data for r in responses] == [expected(256), expected(257)]
        assert peer.received[256][9] == peer.received[0][9] == 0  # SID 0 again
        again = int(session.transport.fast_send is not None)
        resent = [c for c in peer.received if c[13:15] == b"\x01\x00"]
        assert resent == [peer.received[256]] * (1 + again)  # same frame and SID
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.unsolicited) == (258, 2, 0)
        assert (stats.retries, stats.timeouts) == (again, 0)


@on_virtual_time
async def test_a_copy_that_finds_its_sid_reused_by_another_command_teaches_the_linger() -> None:
    """Issue #22, defect 5 (soak seed 44025): the network copies the reply to a write (SID
    0) 0.3 s late; by then SID 0 carries a read (word 256, its reply 0.5 s late). The copy
    has the write's command code, so it answers no read; it is a byte-for-byte copy of the
    SID's last reply all the same, the link's first duplicate: counted as one, it teaches
    the linger (2 x 0.3 s) rather than pass for a stray reply (before: mismatched, linger
    0, and the next copies on the link went unseen)."""

    def handler(cmd: bytes) -> list[Reply]:
        if cmd[10:12] == b"\x01\x02":  # the write
            good = reply(cmd, 0, b"")
            return [(0.0, good), (0.3, good)]
        late = 0.5 if int.from_bytes(cmd[13:15], "big") == 256 else 0.0
        return [(late, reply(cmd, 0, word_data(cmd)))]

    async with (
        udp_responder(handler) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        await session.request(0x01, 0x02, read_params(0) + b"\x12\x34")
        for word in range(1, 257):
            r = await session.request(0x01, 0x01, read_params(word), idempotent=True)
            assert r.data == expected(word), word
        assert peer.received[256][9] == peer.received[0][9] == 0  # SID 0 again
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.mismatched) == (257, 1, 0)
        assert (stats.unsolicited, stats.retries, stats.timeouts) == (0, 0, 0)
        assert session.sids.linger == pytest.approx(0.6)


def copies_of(copied: dict[int, float], late: dict[int, float] | None = None) -> Handler:
    """A peer whose reply to the first read of each word of ``copied`` the network copies
    that many seconds later, and which answers the second read of each word of ``late``
    that many seconds late (its first and every other read: at once; a write: at once,
    or 0.3 s late to word 900)."""
    late = late or {}
    seen: set[int] = set()

    def handler(cmd: bytes) -> list[Reply]:
        word = int.from_bytes(cmd[13:15], "big")
        if cmd[10:12] == b"\x01\x02":
            return [(0.3 if word == 900 else 0.0, reply(cmd, 0, b""))]
        good = reply(cmd, 0, word_data(cmd))
        first = word not in seen
        seen.add(word)
        if first and word in copied:
            return [(0.0, good), (copied[word], good)]
        if not first and word in late:
            return [(late.pop(word), good)]
        return [(0.0, good)]

    return handler


@on_virtual_time
async def test_the_linger_ends_once_the_link_has_shown_no_duplicate_for_a_second() -> None:
    """Issue #22 (soak seeds 30117 and 50279: no free SID long after the faults ended):
    the link duplicated one reply 0.3 s late, so SIDs linger 0.6 s after a reply; 1.2 s
    later no other duplicate has come (:data:`~aiofins.session.sids.QUIET_SPAN`, 1 s):
    the linger falls back to its floor (1 ms) when a request first finds the next SID
    lingering, and the SIDs answered meanwhile are free 1 ms after their reply. 512 reads
    take 1 ms, not 0.6 s (before: the 257th waited for SID 0's linger). The next
    duplicate teaches the linger again."""
    async with (
        udp_responder(copies_of({1: 0.3, 2000: 0.3})) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        for word in range(256):
            await session.request(0x01, 0x01, read_params(word))
        await anyio.sleep(1.5)  # word 1's copy comes at 0.3 s
        assert session.sids.linger == pytest.approx(0.6)
        start = anyio.current_time()
        for word in range(1000, 1512):
            r = await session.request(0x01, 0x01, read_params(word))
            assert r.data == expected(word), word
        assert anyio.current_time() - start < 0.01
        assert session.sids.linger == LINGER_FLOOR
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.sid_exhausted) == (768, 1, 1)
        await session.request(0x01, 0x01, read_params(2000))
        await anyio.sleep(0.5)  # its copy comes
        assert session.sids.linger == pytest.approx(0.6)
        assert (stats.completed, stats.duplicates, stats.timeouts) == (769, 2, 0)
        assert len(peer.received) == 769


@on_virtual_time
async def test_the_linger_lasts_while_duplicates_come() -> None:
    """The quiet span runs from the link's last duplicate, whether or not it made the
    linger grow: word 1's reply is copied 0.3 s late, word 500's (read at 0.8 s) 0.3 s
    late too, at 1.1 s. A burst of reads at 1.2 s (SIDs 1 to 255, then SID 0, which word
    500's read took) finds the SIDs it answered lingering the full 0.6 s: its 257th read
    waits for SID 1's linger to end at 1.8 s (had the quiet span run from the first
    duplicate, the linger would have ended at 1.3 s)."""
    async with (
        udp_responder(copies_of({1: 0.3, 500: 0.3})) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        for word in range(256):
            await session.request(0x01, 0x01, read_params(word))
        await anyio.sleep(0.8)
        await session.request(0x01, 0x01, read_params(500))
        await anyio.sleep(0.4)  # its copy comes at 1.1 s
        start = anyio.current_time()
        for word in range(1000, 1255):
            await session.request(0x01, 0x01, read_params(word))
        assert anyio.current_time() - start < 0.01
        await session.request(0x01, 0x01, read_params(2000))  # SID 0: free at 1.4 s
        await session.request(0x01, 0x01, read_params(2001))  # SID 1: free at 1.8 s
        assert anyio.current_time() - start == pytest.approx(0.6, abs=0.011)
        assert session.sids.linger == pytest.approx(0.6)
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.sid_exhausted) == (514, 2, 2)
        assert len(peer.received) == 514


@on_virtual_time
async def test_a_late_reply_to_a_read_given_up_on_teaches_no_linger() -> None:
    """Issue #22 (soak seed 30117): a read of word 7 under SID 0 is given up on (its reply
    comes 1 s late); the next answer ends its quarantine 0.5 s later, and SID 0 carries a
    write when the late reply comes. That reply is byte for byte SID 0's last one (the
    first read of word 7), but a read under SID 0 was given up on since: it may be (and
    is) that read's late reply (the write's own comes 0.3 s after it was sent), so it is
    counted as mismatched and teaches no linger (before: a duplicate 1 s late, every SID
    lingering 2 s)."""
    async with (
        udp_responder(copies_of({}, late={7: 1.0})) as peer,
        session_for(peer, max_sid_spaces=1, timeout=0.2, retries=0) as session,
    ):
        await session.request(0x01, 0x01, read_params(7))
        for word in range(100, 355):
            await session.request(0x01, 0x01, read_params(word))
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read_params(7))  # SID 0 again
        await anyio.sleep(0.01)
        await session.request(0x01, 0x01, read_params(400))  # the quarantine ends at 0.71
        await anyio.sleep(0.54)
        for word in range(401, 655):
            await session.request(0x01, 0x01, read_params(word))
        write = read_params(900) + b"\x12\x34"
        await session.request(0x01, 0x02, write, timeout=1.0)  # SID 0, at 0.75 s
        assert peer.received[-1][9] == peer.received[256][9] == peer.received[0][9] == 0
        stats = session.stats
        assert (stats.completed, stats.timeouts, stats.mismatched) == (512, 1, 1)
        assert (stats.duplicates, stats.late_replies, stats.unsolicited) == (0, 0, 0)
        assert session.sids.linger == 0.0


@on_virtual_time
async def test_a_read_in_flight_when_the_link_first_shows_a_duplicate_is_held_back_too() -> None:
    """Issue #22, defect 5 (soak seed 50267): the read of word 256 (SID 0 again, without
    retries) is sent before the link has shown any duplicate, so it keeps no plan; the
    link's first duplicate (word 1's reply, 0.15 s late) comes while it waits, and then
    the copy of SID 0's last reply (word 0's, 0.5 s late). A read may be sent again
    whatever its plan: the copy is held back, the read sent once more (where the
    transport sends synchronously) and its own reply answers it (before: word 0's
    data)."""
    async with (
        udp_responder(copies_of_the_first_reply(0.5, 0.6, taught=0.15)) as peer,
        session_for(peer, max_sid_spaces=1, timeout=2.0, retries=0) as session,
    ):
        for word in range(257):
            r = await session.request(0x01, 0x01, read_params(word))
            assert r.data == expected(word), word
        assert peer.received[256][9] == peer.received[0][9] == 0  # SID 0 again
        again = int(session.transport.fast_send is not None)
        resent = [c for c in peer.received if c[13:15] == b"\x01\x00"]
        assert resent == [peer.received[256]] * (1 + again)  # same frame and SID
        stats = session.stats
        assert (stats.completed, stats.duplicates, stats.unsolicited) == (257, 2, 0)
        assert (stats.retries, stats.timeouts) == (again, 0)
        assert session.sids.linger == pytest.approx(1.0)


@asynccontextmanager
async def memnet_plc(
    fate: Fate, plc: VirtualPLC | None = None
) -> AsyncIterator[tuple[Session, list[bytes]]]:
    """A session (one SID space, no retries) to a peer on the in-memory network, which
    answers a read of ``n`` words at D ``w`` with :func:`word_data` (zeros from D1000 on)
    and a write with its end code, or as ``plc`` does (its memory's words); ``fate``
    decides when each packet arrives. The session's
    UDP transport sends synchronously here under trio as under asyncio. Yields the session
    and the commands the peer received."""
    received: list[bytes] = []
    async with MemoryNetwork(fate=fate) as net:
        sock = net.datagram_socket(*PEER)

        async def serve() -> None:
            while True:
                cmd, source = await sock.receive()
                received.append(cmd)
                if plc is not None:
                    if (answer := plc.handle_frame(cmd)) is not None:
                        sock.sendto(answer, source)
                    continue
                zeros = int.from_bytes(cmd[13:15], "big") >= 1000 or cmd[11] == 0x02
                data = bytes(len(word_data(cmd))) if zeros else word_data(cmd)
                sock.sendto(reply(cmd, 0, b"" if cmd[11] == 0x02 else data), source)

        async with anyio.create_task_group() as tg:
            tg.start_soon(serve)
            async with Session(
                UdpTransport(PEER[0], local_host="10.0.0.200", network=net),
                source=FinsAddress(0, 200, 0),
                dest=FinsAddress(0, 1, 0),
                max_sid_spaces=1,
                timeout=2.0,
                retries=0,
            ) as session:
                yield session, received
            tg.cancel_scope.cancel()


@on_virtual_time
async def test_the_link_s_first_copy_of_an_older_reply_never_answers_a_read_of_other_words() -> (
    None
):
    """Issue #22, defect 5 (soak seed 50040: a SID storm on a link that duplicates every
    reply): the link has shown no duplicate yet. Word 0's reply (SID 0) is copied 0.5 s
    late, after SID 0 carried the reads of words 256 and 512; the read of word 512's own
    reply takes 0.6 s, so the copy comes first. A reply to a read that is byte for byte a
    reply its SID carried within the last second, to a request that asked other words, is
    held back and the read sent again at once (same frame and SID): its own reply answers
    it (before: word 0's data). Nothing is learnt from that first sign: no linger."""

    def fate(packet: Packet) -> list[float]:
        if packet.dest == PEER:
            return [0.0]
        word = int.from_bytes(packet.data[14:16], "big") ^ (1 << 12)
        return {0: [0.0, 0.5], 512: [0.6]}.get(word, [0.0])

    async with memnet_plc(fate) as (session, received):
        for word in range(513):
            r = await session.request(0x01, 0x01, read_params(word))
            assert r.data == expected(word), word
        assert anyio.current_time() == pytest.approx(0.6)
        assert received[512][9] == received[256][9] == received[0][9] == 0  # SID 0
        assert received[513:] == [received[512]]  # sent again once, same frame and SID
        await anyio.sleep(1.0)  # the reply to that comes at 1.1 s
        stats = session.stats
        assert (stats.completed, stats.retries, stats.timeouts) == (513, 1, 0)
        assert (stats.duplicates, stats.unsolicited, stats.mismatched) == (2, 0, 0)
        assert session.sids.linger == 0.0


@on_virtual_time
async def test_a_read_of_zeros_like_its_sid_s_last_costs_one_round_trip_and_teaches_nothing() -> (
    None
):
    """The other side of the rule above: reads of zeros of other words, the same bytes as
    their SID's last reply, are held back once each and answered by the reply to their
    second send (one round trip more: the read of D2000's commands take 0.01 s each). A
    poll of the same words under the same SIDs is answered at once; a write's reply, the
    same bytes as its SID's last write's, too (a write is never sent again). No linger,
    no duplicate."""

    def fate(packet: Packet) -> list[float]:
        slow = packet.dest == PEER and packet.data[13:15] == (2000).to_bytes(2, "big")
        return [0.01 if slow else 0.0]

    async with memnet_plc(fate) as (session, received):
        for _ in range(2):  # SIDs 0-255, then the same questions under the same SIDs
            for word in range(1000, 1256):
                assert (await session.request(0x01, 0x01, read_params(word))).data == b"\0\0"
        start = anyio.current_time()
        assert (await session.request(0x01, 0x01, read_params(2000))).data == b"\0\0"
        assert anyio.current_time() - start == pytest.approx(0.02)  # two round trips
        assert received[512][9] == 0 and received[513:] == [received[512]]
        for word in range(3000, 3512):  # SIDs 1-255, 0 ... twice: replies the same bytes
            await session.request(0x01, 0x02, read_params(word) + b"\x12\x34")
        assert len(received) == 514 + 512
        stats = session.stats
        assert (stats.completed, stats.retries, stats.duplicates) == (513 + 512, 1, 0)
        assert session.sids.linger == 0.0


def late_copies(delays: list[list[float]]) -> Fate:
    """A network that delivers each command at once, and each reply as the first entry of
    ``delays`` says when the test put one there (its copies' delays: ``[0.0, 0.3]`` is a
    reply at once and a copy 0.3 s later), else at once."""

    def fate(packet: Packet) -> list[float]:
        return delays.pop(0) if packet.dest != PEER and delays else [0.0]

    return fate


async def calm_link(session: Session, delays: list[list[float]]) -> None:
    """The link shows one duplicate 0.3 s late (the linger: 0.6 s), then none for 1.5 s:
    257 reads later the linger has calmed to its floor (1 ms; ``SidSpace.calm``)."""
    delays.append([0.0, 0.3])
    await session.request(0x01, 0x01, read_d(100))
    await anyio.sleep(1.5)
    assert session.sids.linger == pytest.approx(0.6)
    for word in range(101, 358):
        await session.request(0x01, 0x01, read_d(word))
    assert session.sids.linger == LINGER_FLOOR


async def around(session: Session, word: int, count: int = 255) -> None:
    """``count`` reads of other words (D ``word`` on): the SIDs come round once."""
    for w in range(word, word + count):
        await session.request(0x01, 0x01, read_d(w))


@on_virtual_time
async def test_a_copy_of_an_older_reply_to_the_same_question_never_answers_a_poll() -> None:
    """Issue #22, defect 5 (soak seed 60234): on a link that has shown a duplicate (its
    linger calmed to the floor), the read of D3 gets SID s ([1744]; the network copies
    the reply 0.16 s late); SID s carries a read of D4 x 7 next, then the read of D3 again
    (D3 is now 1745; its own reply takes 0.3 s): the copy of SID s's older reply comes
    first. Byte for byte the reply to the same question, but not the SID's last (another
    question came between): held back, the read sent again at once (same frame and SID),
    and the reply to that answers it: [1745] (before: [1744], the same-question
    exemption took the copy). The read's first reply, late, is a duplicate."""
    plc = VirtualPLC()
    plc.write("D0", range(1000, 2000))
    plc.write("D3", [1744])
    delays: list[list[float]] = []
    async with memnet_plc(late_copies(delays), plc) as (session, received):
        await calm_link(session, delays)
        delays.append([0.0, 0.16])
        assert (await session.request(0x01, 0x01, read_d(3))).data == (1744).to_bytes(2, "big")
        first = len(received) - 1
        await around(session, 400)
        d4 = await session.request(0x01, 0x01, bytes((0x82, 0, 4, 0, 0, 7)))
        assert d4.data == b"".join((1004 + w).to_bytes(2, "big") for w in range(7))
        await around(session, 700)
        plc.write("D3", [1745])
        delays.append([0.3])
        assert (await session.request(0x01, 0x01, read_d(3))).data == (1745).to_bytes(2, "big")
        third = first + 512
        sid = received[first][9]
        assert received[first + 256][9] == received[third][9] == sid  # SID s, three uses
        assert received[third + 1 :] == [received[third]]  # sent again once, same frame
        await anyio.sleep(0.5)  # the read's first reply comes at 0.3 s
        stats = session.stats
        assert (stats.completed, stats.retries, stats.timeouts) == (771, 1, 0)
        assert (stats.duplicates, stats.unsolicited, stats.mismatched) == (3, 0, 0)
        assert session.sids.linger == pytest.approx(0.32)


@on_virtual_time
async def test_a_poll_of_an_unchanged_value_under_its_sid_s_last_reply_is_not_sent_again() -> None:
    """The other side of the rule above: a read of D3 asked again under its SID when the
    SID's last reply answered that very question (a poll, the value unchanged) is answered
    at once by the same bytes, on a link that has shown a duplicate. What the rule costs:
    the same poll after SID s carried another question (D4 x 7) between, within the hold
    window, is held back and sent again once: one round trip more, no linger learnt."""
    plc = VirtualPLC()
    plc.write("D0", range(1000, 2000))
    delays: list[list[float]] = []
    async with memnet_plc(late_copies(delays), plc) as (session, received):
        await calm_link(session, delays)
        first = len(received)
        for _ in range(2):  # D3 twice under SID s: the second's SID's last reply was D3's
            assert (await session.request(0x01, 0x01, read_d(3))).data == (1003).to_bytes(2, "big")
            await around(session, 400)
        assert received[first + 256] == received[first]  # the same frame
        assert len(received) == first + 512  # not sent again
        assert session.stats.retries == 0
        await session.request(0x01, 0x01, bytes((0x82, 0, 4, 0, 0, 7)))  # SID s
        await around(session, 700)
        assert (await session.request(0x01, 0x01, read_d(3))).data == (1003).to_bytes(2, "big")
        assert received[first + 768 :] == [received[first]] * 2  # sent again once
        stats = session.stats
        assert (stats.completed, stats.retries, stats.timeouts) == (258 + 769, 1, 0)
        assert (stats.duplicates, stats.unsolicited) == (2, 0)
        assert session.sids.linger == LINGER_FLOOR
