"""More SID spaces instead of early reuse (issue #12): when every SID of the session's socket
is in flight or lingering, another socket (UDP, its own source node) or FINS/TCP connection is
opened, up to ``max_sid_spaces``; at the cap requests wait, counted and logged. Real loopback
peers, asyncio, uvloop and trio.

The tests that race many reads against the SIDs' linger (a space opens only when the reads
are faster than the linger) run on virtual time (asyncio on looptime, trio's MockClock;
uvloop's clock cannot be virtual): on the wall clock a loaded machine made the reads slower
than the linger, and no space opened (issue #22, defect 6)."""

from __future__ import annotations

import logging
import random
import socket

import anyio
import looptime
import pytest

from aiofins.hooks import EventHooks, SidSpaceChanged
from aiofins.protocol.errors import CommandError, FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.session.nodes import SOURCE_NODES
from aiofins.session.states import LinkState
from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.transport import MemoryTransport, SerialTransport, TcpTransport

from ..virtual_time import on_virtual_time
from .test_session_lifecycle import expected, run_readers
from .test_session_tcp import TcpPeer, tcp_server, tcp_session
from .test_session_udp import (
    Reply,
    client_address,
    read_params,
    reply,
    session_for,
    udp_responder,
    word_data,
)

pytestmark = pytest.mark.anyio

PLC = FinsAddress(0, 1, 0)


class ReuseWatch:
    """The peer's view: for each (source node, SID) when the last reply to its last use goes
    out (duplicates included); another command under it earlier is an early reuse (the same
    frame again is a retransmission, not a reuse)."""

    def __init__(self, duplicate_rate: float, max_delay: float) -> None:
        self.rng = random.Random(12)
        self.rate = duplicate_rate
        self.max_delay = max_delay
        self.last_reply: dict[tuple[int, int], tuple[float, bytes]] = {}
        self.early = 0
        self.nodes: set[int] = set()

    def __call__(self, cmd: bytes) -> list[Reply]:
        now = anyio.current_time()  # the loop's clock, as the session's linger
        use = (cmd[7], cmd[9])  # SA1, SID
        self.nodes.add(cmd[7])
        until, last = self.last_reply.get(use, (0.0, b""))
        if until > now and cmd != last:
            self.early += 1
        good = reply(cmd, 0, word_data(cmd))
        replies = [(0.0, good)]
        done = max(now, until)
        if self.rng.random() < self.rate:
            delay = self.rng.uniform(0.0, self.max_delay)
            replies.append((delay, good))
            done = max(done, now + delay)
        self.last_reply[use] = (done, cmd)
        return replies


@on_virtual_time
async def test_duplicates_past_a_sid_wrap_open_more_spaces_never_reuse_early() -> None:
    """5 % of replies duplicated up to 0.3 s late, SIDs lingering 1 s: one socket carries
    at most 256 requests a second, 20 tasks ask for more. More sockets open, each with its
    own source node; no SID of any is reused while a reply to it may come; 0 wrong values."""
    watch = ReuseWatch(0.05, 0.3)
    events: list[SidSpaceChanged] = []
    async with (
        udp_responder(watch) as peer,
        session_for(
            peer, min_linger=1.0, timeout=5.0, hooks=EventHooks(sid_space_changed=[events.append])
        ) as session,
    ):
        assert session.max_sid_spaces == 4
        with anyio.fail_after(30):
            good, wrong, errors = await run_readers(session, 20, 1200)
        assert (good, wrong, errors) == (1200, 0, [])
        assert watch.early == 0
        stats = session.stats
        assert stats.sid_spaces_opened >= 1 and stats.sid_space_failures == 0
        assert stats.duplicates > 10
        assert session.sid_spaces == 1 + stats.sid_spaces_opened
        # Each socket its own source node, none the PLC's (1) or the session's own (2).
        assert stats.in_flight == 0
        assert len(watch.nodes) == session.sid_spaces and watch.nodes >= {2}
        assert 1 not in watch.nodes
        assert watch.nodes <= SOURCE_NODES.in_use(f"udp://127.0.0.1:{peer.port}")
        opened = [e for e in events if e.new == "OPEN"]
        assert len(opened) == stats.sid_spaces_opened
        assert {e.node for e in opened} == watch.nodes - {2}
        assert [e.old for e in events if e.space == 1][:2] == [None, "OPENING"]
    # Closed with the session: the nodes cool while the lingering SIDs' replies may come.
    assert SOURCE_NODES.in_use(f"udp://127.0.0.1:{peer.port}") <= watch.nodes - {2}


@on_virtual_time
async def test_at_the_cap_requests_wait_counted_and_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    watch = ReuseWatch(0.05, 0.3)
    async with (
        udp_responder(watch) as peer,
        session_for(peer, min_linger=2.0, timeout=10.0, max_sid_spaces=2) as session,
    ):
        with caplog.at_level(logging.WARNING, logger="aiofins.session"), anyio.fail_after(30):
            good, wrong, errors = await run_readers(session, 20, 1000)
        assert (good, wrong, errors) == (1000, 0, [])
        assert watch.early == 0
        assert session.stats.sid_spaces_opened == 1 and session.sid_spaces == 2
        assert session.stats.sid_exhausted > 0
        assert len(watch.nodes) == 2
        capped = [r for r in caplog.records if "in all 2 SID spaces are taken" in r.getMessage()]
        # once per episode (issue #22, defect 5: SIDs come free and run short many times a
        # second within one shortage, and each time was a new warning)
        assert len(capped) == 1 and capped[0].levelno == logging.WARNING


@on_virtual_time
async def test_an_idle_space_is_closed_and_its_node_cools() -> None:
    events: list[SidSpaceChanged] = []
    async with (
        udp_responder() as peer,
        session_for(
            peer,
            min_linger=2.0,
            max_sid_spaces=2,
            hooks=EventHooks(sid_space_changed=[events.append]),
        ) as session,
    ):
        session.spaces.idle_after = 0.2
        good, wrong, errors = await run_readers(session, 10, 300)
        assert (good, wrong, errors) == (300, 0, [])
        assert session.sid_spaces == 2
        with anyio.fail_after(5):
            while session.sid_spaces > 1:
                await anyio.sleep(0.01)
        assert [(e.old, e.new) for e in events] == [
            (None, "OPENING"),
            ("OPENING", "OPEN"),
            ("OPEN", "CLOSING"),
            ("CLOSING", "CLOSED"),
        ]
        node = events[-1].node
        assert node is not None
        # Its SIDs linger up to 2 s after their replies: the node is not given to another
        # socket meanwhile (a late reply would reach it).
        assert node in SOURCE_NODES.in_use(f"udp://127.0.0.1:{peer.port}")
        # Needed again: a fresh socket, with another node.
        good, wrong, errors = await run_readers(session, 10, 300)
        assert (good, wrong) == (300, 0)
        assert session.stats.sid_spaces_opened >= 2
        second = [e for e in events if e.new == "OPEN"][1]
        assert second.space == 2 and second.node not in (node, 2)


@on_virtual_time  # 20 readers must outrun 256 SIDs per second: not on a loaded wall clock
async def test_a_second_fins_tcp_connection_gets_its_node_from_the_plc() -> None:
    plc = VirtualPLC()
    plc.write("D0", [(1 << 12) ^ w for w in range(1000)])
    async with run_simulator(plc, tcp=("127.0.0.1", 0)) as sim:
        transport = TcpTransport("127.0.0.1", sim.tcp_port, connect_timeout=2)
        async with Session(
            transport, source=FinsAddress(0, 0, 0), dest=FinsAddress(0, 1, 0), min_linger=1.0
        ) as session:
            assert session.max_sid_spaces == 2  # FINS/TCP's default
            good, wrong, errors = await run_readers(session, 20, 700, timeout=10.0)
            assert (good, wrong, errors) == (700, 0, [])
            assert session.stats.sid_spaces_opened == 1 and session.sid_spaces == 2
            (space,) = session.spaces.extra
            assert space.source is not None and space.source.node != session.source.node
            assert space.transport.local_node == space.source.node


async def test_max_sid_spaces_is_checked_and_the_memory_transport_can_have_more() -> None:
    async with Session(
        MemoryTransport(VirtualPLC().handle_frame),
        source=FinsAddress(0, 2, 0),
        dest=FinsAddress(0, 1, 0),
        max_sid_spaces=3,
    ) as session:
        assert session.max_sid_spaces == 3  # the memory transport can make more
    serial = SerialTransport("/dev/null")  # one line: one space, whatever is asked
    assert Session(serial, source=PLC, dest=PLC, max_sid_spaces=3).max_sid_spaces == 1
    with pytest.raises(CommandError, match=r"max_sid_spaces 0 out of range 1\.\.254"):
        Session(
            MemoryTransport(VirtualPLC().handle_frame),
            source=FinsAddress(0, 2, 0),
            dest=FinsAddress(0, 1, 0),
            max_sid_spaces=0,
        )


@on_virtual_time
async def test_request_many_uses_more_spaces_too() -> None:
    """A pipelined batch finding every SID taken goes on in another space (opened for it in
    the background) instead of waiting for the linger to end; never an early reuse."""
    watch = ReuseWatch(0.05, 0.3)
    async with (
        udp_responder(watch) as peer,
        session_for(peer, min_linger=1.0, timeout=5.0) as session,
    ):
        with anyio.fail_after(20):
            for start in range(0, 1200, 400):
                reads = [(0x01, 0x01, read_params(w % 4096)) for w in range(start, start + 400)]
                responses = await session.request_many(reads, idempotent=True)
                assert [r.data for r in responses] == [
                    expected(w % 4096) for w in range(start, start + 400)
                ]
        assert watch.early == 0
        assert session.stats.sid_spaces_opened >= 1
        assert len(watch.nodes) == session.sid_spaces


@on_virtual_time
async def test_an_extra_connection_lost_fails_only_its_own_space() -> None:
    await _extra_connection_lost()


def test_an_extra_connection_lost_under_asyncio_run_closes_its_space() -> None:
    """The same under asyncio's own runner (as ``asyncio.run`` starts most applications),
    not anyio's: the reset connection's ``connection_lost`` is an asyncio callback outside
    any task, and closing its space starts a task, which anyio starts only from a task
    (it raised ``NoEventLoopError`` there and the space stayed CLOSING for ever: issue 22's
    soak, a FINS/TCP reset). On looptime's loop (virtual time), with nothing unhandled."""
    unhandled: list[dict[str, object]] = []
    loop = looptime.new_event_loop(start=0.0)
    loop.set_exception_handler(lambda loop, context: unhandled.append(context))
    try:
        loop.run_until_complete(_extra_connection_lost())
    finally:
        loop.run_until_complete(loop.shutdown_asyncgens())
        loop.close()
    assert unhandled == []


async def _extra_connection_lost() -> None:
    events: list[SidSpaceChanged] = []
    async with (
        tcp_server(TcpPeer()) as peer,
        tcp_session(
            peer, min_linger=2.0, hooks=EventHooks(sid_space_changed=[events.append])
        ) as session,
    ):
        good, wrong, errors = await run_readers(session, 10, 300)
        assert (good, wrong, errors) == (300, 0, [])
        assert session.sid_spaces == 2 and peer.connections == 2
        await peer.streams[1].aclose()  # the PLC resets the second connection
        with anyio.fail_after(5):
            while session.sid_spaces > 1:
                await anyio.sleep(0.01)
        assert [e.new for e in events][-2:] == ["CLOSING", "CLOSED"]
        assert session.link_state is LinkState.OPEN  # the session's own link goes on
        assert session.stats.disconnects == 0
        r = await session.request(0x01, 0x01, read_params(3))
        assert r.data == expected(3)


@on_virtual_time  # the own socket's SIDs linger 5 s: on the wall clock a loaded machine took
# longer than that for the 256 reads, the SIDs came back and the extra space was not used
async def test_requests_in_flight_on_every_space_are_counted() -> None:
    def answer_below_1000(cmd: bytes) -> list[Reply]:
        word = int.from_bytes(cmd[13:15], "big")
        return [] if word >= 1000 else [(0.0, reply(cmd, 0, word_data(cmd)))]

    async with (
        udp_responder(answer_below_1000) as peer,
        session_for(peer, min_linger=5.0, max_sid_spaces=2, max_in_flight=10) as session,
    ):
        good, wrong, errors = await run_readers(session, 5, 256)  # the own socket's SIDs linger
        assert (good, wrong, errors) == (256, 0, [])
        async with anyio.create_task_group() as tg:
            for word in (1000, 1001, 1002):
                tg.start_soon(_times_out, session, word)
            with anyio.fail_after(5):
                while len(peer.received) < 259:
                    await anyio.sleep(0.005)
            assert {f[7] for f in peer.received[256:]} == {254}  # the extra socket's node
            assert session.stats.in_flight == 3 and session.sid_spaces == 2
        assert session.stats.in_flight == 0


async def _times_out(session: Session, word: int) -> None:
    with pytest.raises(FinsTimeout):
        await session.request(0x01, 0x01, read_params(word), timeout=0.5)


@on_virtual_time  # the reads must outrun the SIDs' 0.5 s linger for another space to be
# asked for: on the wall clock a loaded machine was slower, and no space was asked for
async def test_a_plc_refusing_another_connection_is_a_counted_failure_not_an_error(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The PLC takes one FINS/TCP connection only: the second space's handshake is refused.
    Counted and logged; the requests wait for the session's own SIDs instead, all answered."""
    plc = VirtualPLC()
    plc.write("D0", [(1 << 12) ^ w for w in range(1000)])
    async with run_simulator(plc, tcp=("127.0.0.1", 0), max_connections=1) as sim:
        transport = TcpTransport("127.0.0.1", sim.tcp_port, connect_timeout=2)
        async with Session(
            transport, source=FinsAddress(0, 0, 0), dest=PLC, min_linger=0.5, timeout=10.0
        ) as session:
            with caplog.at_level(logging.WARNING, logger="aiofins.session"):
                good, wrong, errors = await run_readers(session, 10, 400)
            assert (good, wrong, errors) == (400, 0, [])
            assert session.stats.sid_space_failures >= 1
            assert session.stats.sid_spaces_opened == 0 and session.sid_spaces == 1
            assert session.stats.background_errors == 0 and session.stats.disconnects == 0
            assert any("cannot open another SID space" in r.getMessage() for r in caplog.records)


@on_virtual_time  # thousands of reads against a 1 s timeout: on the wall clock a loaded
# machine timed some out
async def test_replies_all_sent_to_one_port_reach_the_space_they_are_addressed_to() -> None:
    """An Ethernet unit with an IP address table (or static conversion) sends every reply to
    one port, whichever socket its command came from; its DNA/DA1/DA2 names which of our
    nodes it is for (issue #22, defect 2). With extra SID spaces at ``max_in_flight=255``,
    a reply to an extra space's SID came to the session's own socket, where the request
    under the same SID to the same PLC took it: reads returned other reads' words. Each
    reply now reaches the space it is addressed to, counted as misdirected."""
    fixed: list[tuple[str, int]] = []

    def to_the_table_port(cmd: bytes) -> list[Reply]:
        delay = rng.uniform(0.0, 0.002)  # replies overtake one another, as under load
        peer.tg.start_soon(send_later, delay, reply(cmd, 0, word_data(cmd)))
        return []

    async def send_later(delay: float, frame: bytes) -> None:
        await anyio.sleep(delay)
        peer.send(frame, fixed[0])

    rng = random.Random(22)
    async with (
        udp_responder(to_the_table_port) as peer,
        session_for(
            peer, max_in_flight=255, min_linger=0.5, timeout=1.0, breaker_threshold=0
        ) as session,
    ):
        # 255 commands in flight from 4 sockets overflow a default receive buffer (208 KiB)
        peer.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        await session.ensure_open()
        fixed.append(client_address(session))  # the session's own socket: the table's port
        wrong = good = failed = 0

        async def reader(first: int) -> None:
            nonlocal wrong, good, failed
            for i in range(10):  # with the destination check off, 120 of the 2,550 reads
                word = first + i  # returned other reads' words (30 each: 3 x the CPU)
                try:
                    response = await session.request(0x01, 0x01, read_params(word))
                except FinsTimeout:
                    failed += 1
                    continue
                if response.data == ((1 << 12) ^ word).to_bytes(2, "big"):
                    good += 1
                else:
                    wrong += 1

        async with anyio.create_task_group() as tg:
            for task in range(255):
                tg.start_soon(reader, task * 30)
        stats = session.stats
        assert (good, wrong, failed) == (255 * 10, 0, 0)
        assert stats.sid_spaces_opened >= 1 and stats.misdirected > 0
        assert stats.timeouts == stats.late_replies == stats.unsolicited == 0
