"""Read-after-send under asyncio (UDP and FINS/TCP): a reply already queued when the send
returns completes the request with no event-loop pass; the session still yields regularly and
backs off where the attempt never finds anything.

The replies are placed in the client's socket *before* the request is sent (a loopback
``sendto``/``send`` is delivered before it returns), which is what a peer on the same core
does when it answers during the send. The SIDs are predictable: one destination allocates them
in order.
"""

from __future__ import annotations

import asyncio
import os
import socket
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import anyio.lowlevel
import pytest
from anyio.abc import SocketAttribute

from aiofins.protocol.errors import ConnectionLost, FinsTcpError, FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.protocol.tcp import encode_message
from aiofins.session import Session
from aiofins.transport import TcpTransport

from .loop_passes import counting_loop_passes
from .test_session_tcp import TcpPeer, tcp_server, tcp_session
from .test_session_udp import (
    PLC,
    SOURCE,
    Responder,
    client_address,
    read_params,
    session_for,
    udp_responder,
)

#: The asyncio loops: a reply read after the send completes its request with no loop pass.
LOOPS = [
    pytest.param({}, id="asyncio"),
    pytest.param({"use_uvloop": True}, id="uvloop"),
]
#: Every loop: under trio the read after the send saves the reader task's wake-up.
ALL_LOOPS = [*LOOPS, pytest.param({"trio": True}, id="trio")]


def run(main: Callable[[], Awaitable[None]], options: dict[str, Any]) -> None:
    if options.get("trio"):
        anyio.run(main, backend="trio")
        return
    if options:
        pytest.importorskip("uvloop")
    anyio.run(main, backend="asyncio", backend_options=options)


def counting_deliveries(session: Session) -> list[int]:
    """Wrap the transport's read-after-send; the returned list counts [reads, replies they
    delivered] (a reply delivered leaves no request in flight)."""
    poll = session.transport.poll_now
    assert poll is not None
    counts = [0, 0]

    def counting() -> None:
        assert poll is not None
        before = len(session.replies_awaited)
        poll()
        counts[0] += 1
        counts[1] += before - len(session.replies_awaited)

    session.transport.poll_now = counting
    return counts


def placed_reply(sid: int, data: bytes, to: FinsAddress = SOURCE) -> bytes:
    """A 0101 reply from PLC to ``to`` (the session's source) with ``sid``."""
    dna, da1, da2 = to.network, to.node, to.unit
    sna, sa1, sa2 = PLC.network, PLC.node, PLC.unit
    return bytes((0xC0, 0, 2, dna, da1, da2, sna, sa1, sa2, sid, 1, 1, 0, 0)) + data


async def first_sid(peer: Responder, session: Session) -> tuple[int, tuple[str, int]]:
    """Send one request answered the ordinary way; its SID and the session's local address."""
    await session.request(0x01, 0x01, read_params(0))
    peer.handler = lambda cmd: []  # from now on the peer stays silent: replies are placed
    return peer.received[-1][9], client_address(session)


@pytest.mark.parametrize("options", LOOPS)
def test_placed_reply_completes_without_a_loop_pass_yet_yields_every_33(
    options: dict[str, Any],
) -> None:
    async def main() -> None:
        async with udp_responder() as peer, session_for(peer) as session:
            sid, addr = await first_sid(peer, session)
            async with counting_loop_passes() as passes:
                for i in range(1, 101):
                    value = (0x4000 + i).to_bytes(2, "big")
                    peer.sock.sendto(placed_reply((sid + i) & 0xFF, value), addr)
                    response = await session.request(0x01, 0x01, read_params(i))
                    assert response.data == value
            # Waiting through the loop each time would give other tasks at least 100 turns;
            # read-after-send gives them the forced turn after each streak of 32 (and one
            # after the first request's miss).
            assert 3 <= passes.count <= 15, passes.count
            assert session.stats.completed == 101
            assert session.stats.unsolicited == 0 and session.stats.late_replies == 0

    run(main, options)


@pytest.mark.parametrize("options", LOOPS)
def test_cancellation_lands_during_a_run_of_placed_replies(options: dict[str, Any]) -> None:
    async def main() -> None:
        async with udp_responder() as peer, session_for(peer) as session:
            sid, addr = await first_sid(peer, session)
            # Twenty deadlines in a row, each landing within the run (see the test above for
            # why one could go undelivered under uvloop).
            completed = session.stats.completed
            for _ in range(20):
                i = 0
                with anyio.move_on_after(0.01) as scope:
                    while i < 50_000:
                        i += 1
                        sid = (sid + 1) & 0xFF
                        peer.sock.sendto(placed_reply(sid, b"\x00\x01"), addr)
                        await session.request(0x01, 0x01, read_params(1))
                assert scope.cancelled_caught and i < 50_000, i
                # Every request but the cancelled one was answered by its placed reply.
                assert session.stats.completed == completed + i - 1
                completed += i - 1
            assert session.stats.timeouts == 0

    run(main, options)


@pytest.mark.parametrize("options", LOOPS)
def test_fair_turn_parks_the_task_where_anyio_can_cancel_it(options: dict[str, Any]) -> None:
    """anyio's asyncio backend cancels a task only while it is not parked on a completed
    future (it would lose that result), and retries once per loop pass. Under uvloop a reply
    already queued is read before the other tasks run in a pass, so a fair turn that waited
    for its own reply left the task parked on a completed future whenever anything else ran:
    a deadline around a run of placed replies could go undelivered (seen: about one run in
    ten). The fair turn is a bare yield instead."""

    async def main() -> None:
        async with udp_responder() as peer, session_for(peer) as session:
            sid, addr = await first_sid(peer, session)
            host = asyncio.current_task()
            assert host is not None
            parked_on_result: list[bool] = []

            async def watcher() -> None:
                while True:
                    await anyio.sleep(0)
                    waiter = host._fut_waiter  # type: ignore[attr-defined]  # what anyio checks
                    parked_on_result.append(waiter is not None and waiter.done())

            async with anyio.create_task_group() as tg:
                tg.start_soon(watcher)
                await anyio.sleep(0)
                for i in range(1, 201):
                    peer.sock.sendto(placed_reply((sid + i) & 0xFF, b"\x00\x01"), addr)
                    await session.request(0x01, 0x01, read_params(1))
                tg.cancel_scope.cancel()
            # Every fair turn (one per 33 requests) has a pass in which anyio could cancel
            # the task. (Under stock asyncio the task may also wait out a pass on a reply
            # that has come; the next fair turn is cancellable all the same.)
            cancellable = parked_on_result.count(False)
            assert cancellable >= 200 // 33, parked_on_result

    run(main, options)


@pytest.mark.parametrize("options", ALL_LOOPS)
def test_read_after_send_backs_off_when_replies_come_later(options: dict[str, Any]) -> None:
    """The in-test peer answers only after a loop pass: nearly every attempt is skipped."""

    async def main() -> None:
        async with udp_responder() as peer, session_for(peer) as session:
            await session.request(0x01, 0x01, read_params(0))
            counts = counting_deliveries(session)
            for word in range(200):
                response = await session.request(0x01, 0x01, read_params(word))
                assert response.data == (0x1000 | word).to_bytes(2, "big")
            # After misses in a row 0, 1, 2, 4 ... 64 skipped, then one attempt per 65.
            assert 1 <= counts[0] <= 12, counts

    run(main, options)


def test_trio_placed_replies_are_delivered_by_the_read_after_send() -> None:
    """Under trio the request still waits through a checkpoint, but its reply is read right
    after the send instead of by the reader task; other tasks keep running."""

    async def main() -> None:
        async with udp_responder() as peer, session_for(peer) as session:
            sid, addr = await first_sid(peer, session)
            counts = counting_deliveries(session)
            async with counting_loop_passes() as passes:
                for i in range(1, 101):
                    value = (0x4000 + i).to_bytes(2, "big")
                    peer.sock.sendto(placed_reply((sid + i) & 0xFF, value), addr)
                    response = await session.request(0x01, 0x01, read_params(i))
                    assert response.data == value
            # The first read may come too early (the one before was answered by the peer
            # after a pass); every other one finds its reply.
            assert counts[1] >= 98, counts
            assert passes.count >= 90  # a checkpoint per request: other tasks ran all along
            assert session.stats.completed == 101

    anyio.run(main, backend="trio")


def tcp_placed(sid: int, data: bytes, to: FinsAddress) -> bytes:
    """:func:`placed_reply` to ``to`` (the node the server assigned us) in its FINS/TCP
    envelope."""
    return encode_message(2, placed_reply(sid, data, to))


async def first_tcp_sid(peer: TcpPeer, session: Session) -> tuple[int, socket.socket]:
    """One request answered the ordinary way; its SID and a socket on the server's end of
    the connection (a duplicate: the event loop's own socket object refuses ``send``)."""
    await session.request(0x01, 0x01, read_params(0))
    peer.answer = lambda cmd: None  # silent from now on: replies are placed
    fd = peer.streams[-1].extra(SocketAttribute.raw_socket).fileno()
    raw = socket.socket(fileno=os.dup(fd))
    peer.duplicates.append(raw)
    return peer.frames[-1][9], raw


@pytest.mark.parametrize("options", LOOPS)
def test_tcp_placed_reply_completes_without_a_loop_pass(options: dict[str, Any]) -> None:
    async def main() -> None:
        async with tcp_server(TcpPeer()) as peer, tcp_session(peer) as session:
            assert session.transport.poll_now is not None
            sid, raw = await first_tcp_sid(peer, session)
            async with counting_loop_passes() as passes:
                for i in range(1, 101):
                    value = (0x5000 + i).to_bytes(2, "big")
                    raw.send(tcp_placed((sid + i) & 0xFF, value, session.source))
                    response = await session.request(0x01, 0x01, read_params(i))
                    assert response.data == value
            assert 3 <= passes.count <= 15, passes.count  # as over UDP: a turn per 33
            assert session.stats.completed == 101
            assert session.stats.unsolicited == 0 and session.stats.malformed == 0

    run(main, options)


@pytest.mark.parametrize("options", ALL_LOOPS)
def test_tcp_message_split_between_the_read_after_send_and_the_transport(
    options: dict[str, Any],
) -> None:
    """The read-after-send finds half a message; the transport's own read brings the rest:
    one stream, one decoder, the reply is whole."""

    async def main() -> None:
        async with tcp_server(TcpPeer()) as peer, tcp_session(peer) as session:
            sid, raw = await first_tcp_sid(peer, session)
            for i in range(1, 21):
                message = tcp_placed(
                    (sid + i) & 0xFF, (0x6000 + i).to_bytes(2, "big"), session.source
                )
                cut = 4 + i  # inside the envelope, then inside the FINS header
                raw.send(message[:cut])

                def rest(cmd: bytes, tail: bytes = message[cut:]) -> None:
                    raw.send(tail)  # once the request arrives: after the read-after-send
                    return None

                peer.answer = rest
                response = await session.request(0x01, 0x01, read_params(i))
                assert response.data == (0x6000 + i).to_bytes(2, "big")
            assert session.stats.completed == 21 and session.stats.malformed == 0

    run(main, options)


@pytest.mark.parametrize("options", ALL_LOOPS)
def test_tcp_read_after_send_leaves_the_end_of_stream_to_the_transport(
    options: dict[str, Any],
) -> None:
    """A reply and then the server's FIN: the reply completes its request (the read after
    the send finds the reply, then the end of the stream, and leaves that to the transport).
    The next request either went out on the old connection and fails with ConnectionLost
    (asyncio: no loop pass in between), or finds the end already seen and reconnects (trio:
    the reader runs at the first request's checkpoint). Never a hang or a crash."""

    async def main() -> None:
        async with tcp_server(TcpPeer()) as peer, tcp_session(peer) as session:
            sid, raw = await first_tcp_sid(peer, session)
            raw.send(tcp_placed((sid + 1) & 0xFF, b"\x12\x34", session.source))
            raw.shutdown(socket.SHUT_WR)
            response = await session.request(0x01, 0x01, read_params(1))
            assert response.data == b"\x12\x34"
            peer.answer = TcpPeer().answer  # answers again, on a new connection
            outcomes: list[bytes | str] = []
            for word in (2, 3):
                with anyio.fail_after(3):
                    try:
                        response = await session.request(0x01, 0x01, read_params(word))
                        outcomes.append(response.data)
                    except ConnectionLost:
                        outcomes.append("lost")
            assert outcomes[0] in ("lost", (0x1002).to_bytes(2, "big")), outcomes
            assert outcomes[1] == (0x1003).to_bytes(2, "big"), outcomes
            if options.get("trio") is None:
                assert outcomes[0] == "lost"  # asyncio: sent before the end was seen
            assert peer.connections == 2 and session.stats.disconnects == 1

    run(main, options)


def test_trio_tcp_placed_replies_are_delivered_by_the_read_after_send() -> None:
    async def main() -> None:
        async with tcp_server(TcpPeer()) as peer, tcp_session(peer) as session:
            sid, raw = await first_tcp_sid(peer, session)
            counts = counting_deliveries(session)
            for i in range(1, 101):
                value = (0x5000 + i).to_bytes(2, "big")
                raw.send(tcp_placed((sid + i) & 0xFF, value, session.source))
                response = await session.request(0x01, 0x01, read_params(i))
                assert response.data == value
            assert counts[1] >= 98, counts
            assert session.stats.completed == 101 and session.stats.malformed == 0

    anyio.run(main, backend="trio")


@pytest.mark.parametrize("options", ALL_LOOPS)
def test_tcp_broken_stream_found_by_the_read_after_send_ends_the_connection(
    options: dict[str, Any],
) -> None:
    """Junk where a FINS/TCP header should be, read right after a send: the request fails
    with FinsTcpError at once (not after its timeout), the socket is closed, and the next call
    connects again."""

    async def main() -> None:
        async with tcp_server(TcpPeer()) as peer, tcp_session(peer) as session:
            _, raw = await first_tcp_sid(peer, session)
            raw.send(b"HTTP/1.1 200 OK\r\n\r\n")
            with anyio.fail_after(2):  # the request's own timeout is 10 s
                with pytest.raises(FinsTcpError, match="not 'FINS'"):
                    await session.request(0x01, 0x01, read_params(1), timeout=10)
            peer.answer = TcpPeer().answer
            response = await session.request(0x01, 0x01, read_params(2))
            assert response.data == (0x1002).to_bytes(2, "big")
            assert peer.connections == 2 and session.stats.disconnects == 1

    run(main, options)


def test_trio_tcp_broken_stream_read_after_send_while_the_reader_is_due_closes_it() -> None:
    """Junk arrives and wakes the reader task; the request task runs first in that scheduler
    batch (trio orders a batch at random) and its read after the send consumes the junk and
    ends the connection. The reader, already woken (so not told by ``notify_closing``), found
    nothing to read and waited on the socket again: the broken connection stayed open until
    the session closed. Repeated until that order happened a few times."""

    async def main() -> None:
        found = 0
        async with tcp_server(TcpPeer(answer=lambda c: None)) as peer:
            for _ in range(40):
                async with tcp_session(peer) as session:
                    transport = session.transport
                    assert isinstance(transport, TcpTransport)
                    own = transport._raw
                    assert own is not None
                    fd = peer.streams[-1].extra(SocketAttribute.raw_socket).fileno()
                    raw = socket.socket(fileno=os.dup(fd))
                    peer.duplicates.append(raw)
                    raw.send(b"HTTP/1.1 200 OK\r\n\r\n")
                    await anyio.lowlevel.cancel_shielded_checkpoint()  # the reader is due
                    try:
                        await session.request(0x01, 0x01, read_params(1), timeout=0.2)
                    except FinsTcpError:
                        found += 1  # the read after the send met the junk first
                    except FinsTimeout:
                        pass  # the reader met it first; the request went on a new connection
                    await anyio.wait_all_tasks_blocked()
                    assert own.fileno() == -1  # the broken connection is closed
                if found >= 4:
                    break
        assert found >= 4, found

    anyio.run(main, backend="trio")


@pytest.mark.parametrize("options", ALL_LOOPS)
def test_a_request_sent_among_others_turns_the_read_after_send_off_for_a_while(
    options: dict[str, Any],
) -> None:
    """With concurrent callers, the one whose request is momentarily alone must not run its
    round trips one after another through the read after the send while the others wait to
    send theirs together (50 tasks over FINS/TCP on one core fell to a third). A request
    sent while another is in flight turns the read off for the next 64 lone requests."""

    async def main() -> None:
        async with udp_responder() as peer, session_for(peer) as session:
            sid, addr = await first_sid(peer, session)
            counts = counting_deliveries(session)
            sid = (sid + 1) & 0xFF
            words = iter(range(1, 1000))

            async def placed_request() -> None:
                nonlocal sid
                sid = (sid + 1) & 0xFF
                peer.sock.sendto(placed_reply(sid, b"\x00\x07"), addr)
                response = await session.request(0x01, 0x01, read_params(next(words)))
                assert response.data == b"\x00\x07"

            async with anyio.create_task_group() as tg:
                tg.start_soon(session.request, 0x01, 0x01, read_params(0))  # gets sid + 1
                await anyio.wait_all_tasks_blocked()
                for _ in range(5):  # sent while the other is in flight
                    await placed_request()
                peer.sock.sendto(placed_reply((sid - 5) & 0xFF, b"\x00\x00"), addr)
            assert counts[0] <= 1 and counts[1] == 0, counts  # the first one, sent alone
            before = list(counts)
            for _ in range(64):  # alone again, but concurrency was seen: no read yet
                await placed_request()
            assert counts == before, counts
            for _ in range(10):  # then reads again, and they find the placed replies
                await placed_request()
            assert counts[0] - before[0] >= 9 and counts[1] >= 8, counts
            assert session.stats.completed == 81

    run(main, options)
