"""A quarantine ends on evidence that the PLC answers again, not on a fixed time (issue #22,
defect 4), and not before a reply to its request could still come on this link (the soak's
seed 50239). On virtual time: the 18 s of a run take no wall time and every count is
exact."""

from __future__ import annotations

from collections.abc import AsyncIterator, Mapping, Sequence
from contextlib import asynccontextmanager
from typing import Any

import anyio
import pytest
from trio.testing import MockClock

from aiofins.memnet import MemoryNetwork, Packet
from aiofins.protocol.errors import FinsError, FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.simulator import VirtualPLC
from aiofins.transport import MemoryTransport, UdpTransport

from ..virtual_time import on_virtual_time

TIMEOUT = 0.2
READ_D0 = bytes((0x82, 0, 0, 0, 0, 1))


@pytest.fixture
def anyio_backend() -> object:
    """Virtual time: the session follows trio's MockClock."""
    return ("trio", {"clock": MockClock(autojump_threshold=0)})


@pytest.mark.anyio
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


PLC = ("10.0.0.1", 9600)


def read(word: int, count: int) -> bytes:
    """0101 parameters: ``count`` DM words from ``word``."""
    return bytes((0x82, word >> 8, word & 0xFF, 0, count >> 8, count & 0xFF))


def held(word: int, count: int) -> bytes:
    """What the PLC holds there: D\\ *n* holds 1000 + *n*."""
    return b"".join((1000 + w).to_bytes(2, "big") for w in range(word, word + count))


async def read_each(session: Session, words: range) -> dict[int, bytes]:
    """Two words from each of ``words`` at once, one task each: what each read returned."""
    got: dict[int, bytes] = {}

    async def reader(word: int) -> None:
        got[word] = (await session.request(0x01, 0x01, read(word, 2))).data

    async with anyio.create_task_group() as readers:
        for word in words:
            readers.start_soon(reader, word)
    return got


@asynccontextmanager
async def delayed_link(
    commands: Mapping[int, float | list[float]], replies: dict[int, float], **options: Any
) -> AsyncIterator[tuple[Session, list[bytes]]]:
    """A session (one SID space, 255 in flight, timeout 1 s, no retries; ``options``
    change these) with a VirtualPLC holding ``1000 + w`` in D``w`` over UDP on memnet; a
    command reading from word ``w`` takes ``commands[w]`` to the PLC (a list: one delay
    per transmission, in order), a reply whose first word is D``w``'s ``replies[w]`` back
    (else no time). Yields the session and the commands as the PLC received them."""
    plc = VirtualPLC()
    plc.write("D0", [1000 + w for w in range(600)])
    received: list[bytes] = []

    def fate(packet: Packet) -> Sequence[float]:
        data = packet.data
        if packet.dest == PLC:
            delay = commands.get(int.from_bytes(data[13:15], "big"), 0.0)
            return [delay.pop(0) if isinstance(delay, list) else delay]
        return [replies.get(int.from_bytes(data[14:16], "big") - 1000, 0.0)]

    async with MemoryNetwork(fate=fate) as net:
        sock = net.datagram_socket(*PLC)

        async def serve() -> None:
            while True:
                data, source = await sock.receive()
                received.append(data)
                reply = plc.handle_frame(data)
                if reply is not None:
                    sock.sendto(reply, source)

        async with anyio.create_task_group() as tg:
            tg.start_soon(serve)
            transport = UdpTransport(PLC[0], local_host="10.0.0.200", network=net)
            async with Session(
                transport,
                source=FinsAddress(0, 200, 0),
                dest=FinsAddress(0, 1, 0),
                **{
                    "max_sid_spaces": 1,
                    "max_in_flight": 255,
                    "timeout": 1.0,
                    "retries": 0,
                    **options,
                },
            ) as session:
                yield session, received
            tg.cancel_scope.cancel()


@pytest.mark.parametrize("shown", ["answered", "late"])
@on_virtual_time
async def test_a_late_reply_never_reaches_a_sid_freed_by_a_younger_request_s_answer(
    shown: str,
) -> None:
    """The quarantine's evidence rule (the soak's seed 50239, one UDP socket). A read of
    D10 x 2 is given up on after 0.05 s; its command is 0.4 s on its way to the PLC and
    its reply 0.25 s on the way back, so the PLC takes it after a younger read and its
    words come 0.65 s after it was sent. The younger read, of D20 x 2, sent when the
    first was given up on, is answered at once: the evidence that the PLC answers ended
    the first read's quarantine 0.5 s later, at 2.55 s. At 2.6 s 255 reads, whose replies
    take 0.2 s, took every SID but the younger read's, the quarantined one included: the
    late reply answered the read under it with D10's words (two words, like its own).

    The link had shown a round trip that long before: a read answered after 0.65 s
    (``answered``), or one given up on whose reply came 0.65 s after it was sent
    (``late``). A quarantine now ends on that evidence no sooner than twice the slowest
    round trip the link has shown after its request was sent (2.0 + 1.3 s): the 255 reads
    leave the quarantined SID alone, take the younger read's, and each gets its own words;
    the late reply is counted as late."""
    commands = {1: 0.3, 10: 0.4}  # word read -> how long its command takes to the PLC
    replies = {1: 0.35, 10: 0.25}  # first word read -> how long its reply takes back
    replies.update((w, 0.2) for w in range(100, 355))
    async with delayed_link(commands, replies) as (session, received):
        if shown == "answered":  # a round trip of 0.65 s, in time
            r = await session.request(0x01, 0x01, read(1, 1))
            assert r.data == held(1, 1)
            assert anyio.current_time() == pytest.approx(0.65, abs=1e-5)
        else:  # given up on at 0.1 s; its reply comes 0.65 s after its send
            with pytest.raises(FinsTimeout):
                await session.request(0x01, 0x01, read(1, 1), timeout=0.1)
        await anyio.sleep(2.0 - anyio.current_time())
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read(10, 2), timeout=0.05)
        r = await session.request(0x01, 0x01, read(20, 2))
        assert r.data == held(20, 2)
        assert anyio.current_time() == pytest.approx(2.05, abs=1e-5)
        await anyio.sleep(0.55)
        assert await read_each(session, range(100, 355)) == {
            word: held(word, 2) for word in range(100, 355)
        }
        assert anyio.current_time() == pytest.approx(2.8, abs=1e-5)
        # the SIDs as the PLC took them: 0 (D1), 2 (D20) before 1 (D10, delayed),
        # then 3..255, 0 and 2 again (1 still quarantined)
        assert [f[9] for f in received] == [0, 2, 1, *range(3, 256), 0, 2]
        stats, late = session.stats, int(shown == "late")
        assert (stats.completed, stats.timeouts) == (257 - late, 1 + late)
        assert (stats.late_replies, stats.unsolicited, stats.duplicates) == (1 + late, 0, 0)


@pytest.mark.parametrize("shown", ["answered", "late"])
@on_virtual_time
async def test_a_longer_round_trip_shown_after_the_evidence_keeps_the_sids_it_freed(
    shown: str,
) -> None:
    """A delay episode longer than any round trip shown before (the soak's seed 53003). A
    read answered after 0.3 s is the slowest the link has shown. At 2.0 s a read of D5 x 2
    is sent, its round trip 0.55 s; at 2.05 s a read of D10 x 2, given up on after 0.05 s,
    its round trip 0.8 s; at 2.1 s a younger read, of D20 x 2, is answered at once. That
    evidence ended D10's quarantine at ``max(2.1 + 0.5, 2.05 + 2 x 0.3)`` = 2.65 s; at
    2.7 s reads whose replies take 0.2 s took every free SID, D10's among them, and its
    late reply at 2.85 s answered one of them with D10's words (two words, like its own).

    D5's reply, in time (``answered``: its caller waits 1 s) or late (``late``: given up on
    after 0.05 s, its reply within 0.5 s of the evidence), shows a round trip of 0.55 s at
    2.55 s, before D10's quarantine ended: a longer round trip than the link had shown
    extends the quarantines the evidence ended to twice it after their requests were sent
    (2.05 + 1.1 s). The reads leave D10's SID alone and each gets its own words; D10's
    reply is counted as late."""
    commands = {1: 0.15, 5: 0.3, 10: 0.5}  # word read -> how long its command takes to the PLC
    replies = {1: 0.15, 5: 0.25, 10: 0.3}  # first word read -> how long its reply takes back
    replies.update((w, 0.2) for w in range(100, 356))
    async with delayed_link(commands, replies) as (session, received):
        r = await session.request(0x01, 0x01, read(1, 1))  # the slowest: 0.3 s
        assert r.data == held(1, 1)
        assert anyio.current_time() == pytest.approx(0.3, abs=1e-5)
        await anyio.sleep(2.0 - anyio.current_time())
        words: dict[int, bytes] = {}
        timeouts: list[int] = []

        async def reader(word: int, timeout: float | None = None) -> None:
            try:
                r = await session.request(0x01, 0x01, read(word, 2), timeout=timeout)
            except FinsTimeout:
                timeouts.append(word)
            else:
                words[word] = r.data

        async with anyio.create_task_group() as episode:
            episode.start_soon(reader, 5, 1.0 if shown == "answered" else 0.05)
            await anyio.sleep(0.05)
            await reader(10, 0.05)
            await reader(20)
            assert anyio.current_time() == pytest.approx(2.1, abs=1e-5)
            await anyio.sleep(0.6)
            many = range(100, 355 if shown == "answered" else 354)
            for word in many:
                episode.start_soon(reader, word)
        assert anyio.current_time() == pytest.approx(2.9, abs=1e-5)
        late = int(shown == "late")
        assert timeouts == [5, 10][1 - late :]
        assert words == {w: held(w, 2) for w in [*[5][late:], 20, *many]}
        # the SIDs as the PLC took them: 0 (D1), 3 (D20), 1 (D5) and 2 (D10)
        # delayed, then 4..255, 0, 1 (D5 answered in time, else quarantined) and 3,
        # never 2 (D10 quarantined again)
        again = [1, 3] if shown == "answered" else [3]
        assert [f[9] for f in received] == [0, 3, 1, 2, *range(4, 256), 0, *again]
        stats = session.stats
        assert (stats.completed, stats.timeouts) == (len(many) + 3 - late, 1 + late)
        assert (stats.late_replies, stats.unsolicited, stats.duplicates) == (1 + late, 0, 0)


@on_virtual_time
async def test_the_reply_to_another_transmission_never_reaches_a_sid_freed_by_the_first() -> None:
    """A late reply to a request sent twice (the soak's seed 60380). A read of D1 takes SID
    0; a read of D10 x 2, SID 1, is sent at 0 s and again at 0.033 s (one retry: a third
    of its timeout, no round trip measured yet) and given up on at 0.1 s; a read of
    D20 x 2, SID 2, is answered at once (the evidence: the quarantine would end at 0.6 s).
    The first transmission's reply comes at 0.4 s (0.2 s each way); the second's command
    is 0.8 s on its way and its reply comes at 1.033 s. The first late reply ended the
    quarantine 0.5 s later, at 0.9 s; at 0.95 s 255 reads, whose replies take 0.2 s, took
    every SID but D20's, the quarantined one included, and the second late reply
    answered the read under it with D10's words (two words, like its own).

    A late reply to a request sent more than once keeps its SID as long as a SID answered
    after a retransmission lingers: twice the time since its first send (0.4 + 0.8 s). The
    255 reads leave SID 1 alone, take D20's, and each gets its own words; both replies to
    D10 are counted as late."""
    commands: dict[int, float | list[float]] = {10: [0.2, 0.8]}
    replies = {10: 0.2}
    replies.update((w, 0.2) for w in range(100, 355))
    async with delayed_link(commands, replies, retries=1) as (session, received):
        assert (await session.request(0x01, 0x01, read(1, 1))).data == held(1, 1)
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read(10, 2), timeout=0.1, idempotent=True)
        assert (await session.request(0x01, 0x01, read(20, 2))).data == held(20, 2)
        await anyio.sleep(0.95 - anyio.current_time())
        assert await read_each(session, range(100, 355)) == {
            word: held(word, 2) for word in range(100, 355)
        }
        assert anyio.current_time() == pytest.approx(1.15, abs=1e-5)
        # the SIDs as the PLC took them: 0 (D1), 2 (D20), 1 twice (D10's transmissions,
        # at 0.2 and 0.833 s), then 3..255, 0 and 2, never 1 (quarantined until 1.2 s)
        assert [f[9] for f in received] == [0, 2, 1, 1, *range(3, 256), 0, 2]
        stats = session.stats
        assert (stats.completed, stats.timeouts, stats.retries) == (257, 1, 1)
        assert (stats.late_replies, stats.unsolicited, stats.duplicates) == (2, 0, 0)
