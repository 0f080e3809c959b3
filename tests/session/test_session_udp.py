"""Session over real loopback UDP against an in-test FINS responder (asyncio and trio).

The responder answers hand-built frames; each test gives it a handler that decides, per
command, which replies to send and when, so it can misbehave on purpose.
"""

from __future__ import annotations

import math
import re
import socket
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import anyio
import pytest
from anyio.abc import TaskGroup

from aiofins.protocol.errors import (
    CommandError,
    CommandRejectedError,
    ParameterError,
    RelayError,
)
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.transport import UdpTransport

from ..virtual_time import on_virtual_time, run_on_virtual_time

SOURCE = FinsAddress(0, 2, 0)
PLC = FinsAddress(0, 1, 0)

#: A reply to send: (delay in seconds, frame bytes).
Reply = tuple[float, bytes]
Handler = Callable[[bytes], list[Reply]]


def reply(
    cmd: bytes, end_code: int = 0, data: bytes = b"", *, icf: int = 0xC0, trailer: bytes = b""
) -> bytes:
    """The response to command ``cmd``, built by hand: addresses swapped, SID/code echoed."""
    return (
        bytes((icf, 0, 2, cmd[6], cmd[7], cmd[8], cmd[3], cmd[4], cmd[5], cmd[9], cmd[10], cmd[11]))
        + end_code.to_bytes(2, "big")
        + trailer
        + data
    )


def read_params(word: int, count: int = 1) -> bytes:
    """0101 parameters: DM (0x82) word ``word``, bit 0, ``count`` words."""
    return bytes((0x82, word >> 8, word & 0xFF, 0, count >> 8, count & 0xFF))


def word_data(cmd: bytes) -> bytes:
    """What the responder's memory holds: word w of node n reads (n << 12) ^ w."""
    node = cmd[4]
    word = int.from_bytes(cmd[13:15], "big")
    count = int.from_bytes(cmd[16:18], "big")
    return b"".join((((node << 12) ^ (word + i)) & 0xFFFF).to_bytes(2, "big") for i in range(count))


def answer(cmd: bytes) -> list[Reply]:
    return [(0.0, reply(cmd, 0, word_data(cmd)))]


@dataclass
class Responder:
    """A FINS peer on a loopback UDP socket."""

    handler: Handler
    sock: socket.socket
    tg: TaskGroup
    port: int
    received: list[bytes] = field(default_factory=list)
    #: The address each source node (SA1) last sent from: where an Ethernet unit sends the
    #: replies to that node (a session's extra SID spaces are sockets with nodes of their own).
    senders: dict[int, tuple[str, int]] = field(default_factory=dict)

    def send(self, frame: bytes, addr: tuple[str, int]) -> None:
        self.sock.sendto(frame, addr)


@asynccontextmanager
async def udp_responder(handler: Handler = answer) -> AsyncIterator[Responder]:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        async with anyio.create_task_group() as tg:
            responder = Responder(handler, sock, tg, sock.getsockname()[1])

            async def delayed(delay: float, frame: bytes, addr: tuple[str, int]) -> None:
                await anyio.sleep(delay)
                responder.send(frame, addr)

            async def serve() -> None:
                while True:
                    await anyio.wait_readable(sock)
                    try:
                        data, addr = sock.recvfrom(4096)
                    except BlockingIOError:
                        continue
                    responder.received.append(data)
                    if len(data) > 7:
                        responder.senders[data[7]] = addr
                    for delay, frame in responder.handler(data):
                        if delay <= 0:
                            responder.send(frame, addr)
                        else:
                            tg.start_soon(delayed, delay, frame, addr)

            tg.start_soon(serve)
            yield responder
            tg.cancel_scope.cancel()


def client_address(session: Session) -> tuple[str, int]:
    """Where the session's UDP socket is bound: the address a responder sends replies to."""
    transport = session.transport
    assert isinstance(transport, UdpTransport)
    address = transport.local_address
    assert address is not None
    return address


def session_for(responder: Responder, **options: object) -> Session:
    return Session(
        UdpTransport("127.0.0.1", responder.port),
        source=SOURCE,
        dest=PLC,
        **options,  # type: ignore[arg-type]
    )


@pytest.mark.anyio
async def test_read_sends_exact_bytes_and_returns_data() -> None:
    async with udp_responder() as peer, session_for(peer) as session:
        response = await session.request(0x01, 0x01, read_params(100, 2), idempotent=True)
        assert response.data == bytes.fromhex("1064 1065".replace(" ", ""))
        assert response.end_code.raw == 0
        assert response.mrc == 0x01 and response.src == 0x01
        assert response.header.source == PLC and response.header.destination == SOURCE
        sent = peer.received[0]
        # ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2 SID MRC SRC params
        assert sent[:9] == bytes((0x80, 0x00, 0x02, 0, 1, 0, 0, 2, 0))
        assert sent[10:] == bytes((0x01, 0x01)) + read_params(100, 2)
        assert session.stats.completed == 1 and session.stats.in_flight == 0
        assert session.stats.latency_mean > 0


@pytest.mark.anyio
async def test_thousand_concurrent_requests_each_get_their_own_data() -> None:
    """1,000 requests to 10 nodes x 100 words; replies come back in reverse batches."""
    held: list[bytes] = []

    def reorder(cmd: bytes) -> list[Reply]:
        held.append(cmd)
        if len(held) < 7:
            return []
        batch = [(0.0, reply(c, 0, word_data(c))) for c in reversed(held)]
        held.clear()
        return batch

    async def flush_stragglers(peer: Responder) -> None:
        while True:  # answer whatever waits for a batch that will never fill
            await anyio.sleep(0.02)
            if held:
                cmds = list(held)
                held.clear()
                addr = ("127.0.0.1", local_port)
                for c in reversed(cmds):
                    peer.send(reply(c, 0, word_data(c)), addr)

    results: dict[tuple[int, int], bytes] = {}
    async with udp_responder(reorder) as peer, session_for(peer, max_in_flight=5) as session:
        address = session.transport.local_address  # type: ignore[attr-defined]
        local_port = address[1]
        peer.tg.start_soon(flush_stragglers, peer)

        async def one(node: int, word: int) -> None:
            r = await session.request(
                0x01, 0x01, read_params(word, 1), dest=FinsAddress(0, node, 0), timeout=5
            )
            results[(node, word)] = r.data

        async with anyio.create_task_group() as tg:
            for word in range(100):
                for node in range(1, 11):
                    tg.start_soon(one, node, 1000 + word)
    assert len(results) == 1000
    for (node, word), data in results.items():
        assert data == (((node << 12) ^ word) & 0xFFFF).to_bytes(2, "big")
    assert session.stats.completed == 1000
    assert session.stats.timeouts == 0


@pytest.mark.anyio
async def test_in_flight_cap_per_destination() -> None:
    seen_max = 0
    waiting: list[bytes] = []
    want = 3
    arrived = anyio.Event()

    def hold(cmd: bytes) -> list[Reply]:
        nonlocal seen_max
        waiting.append(cmd)
        seen_max = max(seen_max, len(waiting))
        if len(waiting) >= want:
            arrived.set()
        return []

    async with udp_responder(hold) as peer, session_for(peer, max_in_flight=3) as session:
        addr = ("127.0.0.1", session.transport.local_address[1])  # type: ignore[attr-defined]

        called: list[int] = []

        async def one(word: int) -> None:
            called.append(word)  # no await between this and the request: queue order
            await session.request(0x01, 0x01, read_params(word), timeout=5)

        async with anyio.create_task_group() as tg:
            for word in range(10):
                tg.start_soon(one, word)
            remaining = 10
            while remaining:
                want = min(3, remaining)
                await arrived.wait()
                arrived = anyio.Event()
                assert session.stats.in_flight == want
                batch = list(waiting)
                waiting.clear()
                remaining -= len(batch)
                for c in batch:
                    peer.send(reply(c, 0, word_data(c)), addr)
    assert seen_max == 3
    assert session.stats.completed == 10
    # FIFO: each freed batch of slots went to the next callers in queue order (woken
    # together, they may send in any order within the batch).
    sent = [int.from_bytes(c[13:15], "big") for c in peer.received]
    for i in range(0, 10, 3):
        assert sorted(sent[i : i + 3]) == sorted(called[i : i + 3])


@pytest.mark.anyio
async def test_end_code_error_is_raised_with_its_class() -> None:
    def bad_area(cmd: bytes) -> list[Reply]:
        return [(0.0, reply(cmd, 0x1101))]

    async with udp_responder(bad_area) as peer, session_for(peer) as session:
        with pytest.raises(ParameterError) as info:
            await session.request(0x01, 0x01, read_params(0))
        assert info.value.code == 0x1101
        assert info.value.command_code == 0x0101
        assert session.stats.end_code_errors == 1


@pytest.mark.anyio
async def test_cpu_error_flags_ride_on_the_response() -> None:
    def flagged(cmd: bytes) -> list[Reply]:
        return [(0.0, reply(cmd, 0x0040, b"\x12\x34"))]

    async with udp_responder(flagged) as peer, session_for(peer) as session:
        response = await session.request(0x01, 0x01, read_params(0))
        assert response.data == b"\x12\x34"
        assert response.non_fatal_cpu_error and not response.fatal_cpu_error
        assert response.end_code.is_normal and response.end_code.raw == 0x0040


@pytest.mark.anyio
async def test_fatal_flag_0080_is_not_an_error() -> None:
    async with (
        udp_responder(lambda c: [(0.0, reply(c, 0x0080, b"\x00\x01"))]) as peer,
        session_for(peer) as session,
    ):
        response = await session.request(0x01, 0x01, read_params(0))
        assert response.fatal_cpu_error and response.data == b"\x00\x01"


@pytest.mark.anyio
async def test_relay_error_names_the_relay_point() -> None:
    def relay(cmd: bytes) -> list[Reply]:
        return [(0.0, reply(cmd, 0x8000 | 0x0101, trailer=bytes((3, 17))))]

    async with udp_responder(relay) as peer, session_for(peer) as session:
        with pytest.raises(RelayError) as info:
            await session.request(0x01, 0x01, read_params(0))
        assert (info.value.network, info.value.node) == (3, 17)
        assert info.value.code == 0x0101


@pytest.mark.anyio
async def test_busy_end_code_is_retried_then_succeeds() -> None:
    calls = 0

    def busy_twice(cmd: bytes) -> list[Reply]:
        nonlocal calls
        calls += 1
        if calls <= 2:
            return [(0.0, reply(cmd, 0x2604))]
        return answer(cmd)

    async with udp_responder(busy_twice) as peer, session_for(peer, busy_backoff=0.001) as s:
        response = await s.request(0x01, 0x02, read_params(5) + b"\x00\x07")
        assert response.end_code.raw == 0
        assert s.stats.busy_retries == 2
        sids = [frame[9] for frame in peer.received]
        assert len(set(sids)) == 3  # each attempt with a fresh SID


@pytest.mark.anyio
async def test_busy_forever_raises_command_rejected() -> None:
    async with (
        udp_responder(lambda c: [(0.0, reply(c, 0x2605))]) as peer,
        session_for(peer, busy_retries=1, busy_backoff=0.001) as session,
    ):
        with pytest.raises(CommandRejectedError) as info:
            await session.request(0x04, 0x01)
        assert info.value.is_busy
        assert len(peer.received) == 2


@pytest.mark.anyio
async def test_icf_c1_reply_is_accepted() -> None:
    async with (
        udp_responder(lambda c: [(0.0, reply(c, 0, b"\xab\xcd", icf=0xC1))]) as peer,
        session_for(peer) as session,
    ):
        assert (await session.request(0x01, 0x01, read_params(1))).data == b"\xab\xcd"


@pytest.mark.anyio
async def test_reply_from_real_network_matches_request_to_network_zero() -> None:
    def renumbered(cmd: bytes) -> list[Reply]:
        frame = bytearray(reply(cmd, 0, b"\x00\x09"))
        frame[6] = 5  # the PLC answers with its network number, not 0
        return [(0.0, bytes(frame))]

    async with udp_responder(renumbered) as peer, session_for(peer) as session:
        assert (await session.request(0x01, 0x01, read_params(1))).data == b"\x00\x09"


@pytest.mark.anyio
async def test_relay_error_from_the_relay_point_reaches_its_request() -> None:
    """The relay point answers with its own address as source, not the destination's."""

    def relay_point(cmd: bytes) -> list[Reply]:
        frame = bytearray(reply(cmd, 0x8000 | 0x0501, trailer=bytes((0, 7))))
        frame[6:9] = bytes((0, 7, 0))  # SNA SA1 SA2 of the gateway node 7
        return [(0.0, bytes(frame))]

    async with udp_responder(relay_point) as peer, session_for(peer) as session:
        with pytest.raises(RelayError) as info:
            await session.request(0x01, 0x01, read_params(0), dest=FinsAddress(5, 9, 0))
        assert (info.value.network, info.value.node) == (0, 7)
        assert info.value.code == 0x0501


@pytest.mark.anyio
async def test_relay_errors_reach_their_requests_when_several_destinations_share_a_sid() -> None:
    """Found by an audit: SIDs were counted per destination, so a read of the relay PLC
    1.10.0 and a read routed through it to 3.5.0 both had SID 0. The relay error for 3.5.0
    (from 1.10.0) went to the 1.10.0 read, whose own reply was then dropped as a duplicate;
    two routed reads sharing a SID both timed out. A SID is now unique across destinations."""

    def relay_plc(cmd: bytes) -> list[Reply]:
        if cmd[3] == 1:  # for the relay PLC itself: an answer, a little later
            return [(0.02, reply(cmd, 0, b"\x00\x2a"))]
        frame = bytearray(reply(cmd, 0x8000 | 0x0205, trailer=bytes((1, 10))))
        frame[6:9] = bytes((1, 10, 0))  # from the relay point 1.10.0
        return [(0.0, bytes(frame))]

    async with udp_responder(relay_plc) as peer, session_for(peer, timeout=1.0) as session:
        outcome: dict[str, object] = {}

        async def read(dest: FinsAddress) -> None:
            try:
                outcome[str(dest)] = (
                    await session.request(0x01, 0x01, read_params(0), dest=dest)
                ).data
            except RelayError as exc:
                outcome[str(dest)] = (exc.network, exc.node)

        async with anyio.create_task_group() as tg:
            for dest in (FinsAddress(1, 10, 0), FinsAddress(3, 5, 0), FinsAddress(4, 6, 0)):
                tg.start_soon(read, dest)
        assert outcome == {"1.10.0": b"\x00\x2a", "3.5.0": (1, 10), "4.6.0": (1, 10)}
        sids = [frame[9] for frame in peer.received]
        assert len(set(sids)) == 3
        stats = session.stats
        assert (stats.timeouts, stats.duplicates, stats.unsolicited) == (0, 0, 0)


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("max_in_flight", 0, "max_in_flight 0 out of range 1..255"),
        ("timeout", 0, "timeout 0 must be positive"),
        ("retries", -1, "retries -1 must not be negative"),
        ("busy_retries", -1, "busy_retries -1 must not be negative"),
        ("busy_backoff", -0.1, "busy_backoff -0.1 must not be negative"),
        ("quarantine_factor", 0, "quarantine_factor 0 must be positive"),
        ("min_quarantine", -1, "min_quarantine -1 must be 0 or more seconds"),
        ("reconnect_backoff", (1.0, 0.5), "reconnect_backoff (1.0, 0.5) must be (min, max)"),
        ("gct", 256, "GCT 256 out of range"),
    ],
)
def test_bad_session_options_are_refused(option: str, value: object, message: str) -> None:
    with pytest.raises(CommandError, match=re.escape(message)):
        Session(
            UdpTransport("127.0.0.1", 9600),
            source=FinsAddress(0, 2, 0),
            dest=FinsAddress(0, 1, 0),
            **{option: value},  # type: ignore[arg-type]
        )


@pytest.mark.anyio
async def test_bad_per_call_timeout_or_retries_are_refused_before_sending() -> None:
    async with udp_responder(answer) as responder, session_for(responder) as s:
        for kwargs, message in (
            ({"timeout": 0}, "timeout 0 must be positive"),
            ({"retries": -1}, "retries -1 must not be negative"),
        ):
            with pytest.raises(CommandError, match=message):
                await s.request(0x01, 0x01, read_params(0), **kwargs)  # type: ignore[arg-type]
            with pytest.raises(CommandError, match=message):
                await s.request_many([(0x01, 0x01, read_params(0))] * 2, **kwargs)  # type: ignore[arg-type]
        assert responder.received == []


@pytest.mark.anyio
async def test_parameters_that_are_not_bytes_leave_nothing_behind() -> None:
    """A bad parameter block raises before the request is registered: no SID held (so no
    late timeout), nothing sent."""
    async with udp_responder(answer) as responder, session_for(responder, timeout=0.2) as s:
        with pytest.raises(TypeError):
            await s.request(0x01, 0x01, "abc")  # type: ignore[arg-type]
        assert s.stats.in_flight == 0
        with pytest.raises(TypeError, match="command parameters must be bytes, got str"):
            await s.request_many([(0x01, 0x01, read_params(0)), (0x01, 0x01, "abc")])  # type: ignore[list-item]
        assert s.stats.in_flight == 0
        assert (await s.request(0x01, 0x01, read_params(5))).data == (
            (PLC.node << 12) ^ 5
        ).to_bytes(2, "big")
        assert len(responder.received) == 1 and s.stats.timeouts == 0


@pytest.mark.anyio
@pytest.mark.parametrize("timeout", [None, 0.5])
async def test_command_codes_that_do_not_fit_raise_before_anything_is_sent(
    timeout: float | None,
) -> None:
    """A command code out of 0..255, or not an int, raises the error that says so with
    nothing sent and the slot given back, whether the call takes ``request``'s own common
    case (the session's options: the frame's packing finds it) or ``begin`` (an option
    given: its check finds it)."""
    async with udp_responder(answer) as responder, session_for(responder, max_in_flight=1) as s:
        for _ in range(2):  # the second time the slot others gave back (max_in_flight=1)
            reply = await s.request(0x01, 0x01, read_params(5), timeout=timeout)
            assert reply.data == ((PLC.node << 12) ^ 5).to_bytes(2, "big")
            for mrc, src, error, message in (
                (0x100, 0x01, CommandError, "command code 0x100/0x1 out of range 0..255"),
                (0x01, -1, CommandError, "command code 0x1/-0x1 out of range 0..255"),
                (1.0, 0x01, TypeError, "float"),  # (begin's check: an unsupported operand)
            ):
                with pytest.raises(error, match=re.escape(message)):
                    await s.request(mrc, src, read_params(0), timeout=timeout)  # type: ignore[arg-type]
                assert s.stats.in_flight == 0
        assert len(responder.received) == 2


@on_virtual_time
async def test_a_slow_reply_over_udp_is_retransmitted_after_the_rto() -> None:
    """Over UDP a datagram may be lost: once the round trip is measured (RTO at its 20 ms
    floor), a request whose reply takes 60 ms is sent again (same frame and SID) before it
    comes; the call still gets that reply. On virtual time (uvloop's clock cannot be
    virtual): on a loaded wall clock the first round trip measured could exceed 60 ms,
    and nothing was sent again."""
    delays = [0.0, 0.06]

    def slow_second(cmd: bytes) -> list[Reply]:
        delay = delays[0] if len(delays) == 1 else delays.pop(0)
        return [(delay, reply(cmd, 0, word_data(cmd)))]

    async with (
        udp_responder(slow_second) as responder,
        session_for(responder, retries=2, timeout=1) as session,
    ):
        await session.request(0x01, 0x01, read_params(0), idempotent=True)  # RTT measured
        slow = await session.request(0x01, 0x01, read_params(1), idempotent=True)
        assert slow.data == word_data(responder.received[1])
        assert session.stats.retries >= 1
        assert len(responder.received) >= 3
        assert len(set(responder.received[1:])) == 1  # the same frame, the same SID


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_answered_requests_do_not_wake_the_deadline_watcher(backend: str) -> None:
    """A paced caller (one read every 50 ms, each answered long before its 20 ms RTO): once
    the watcher's timer has fired for nothing (after the first read), a reply that leaves
    no deadline cancels the timer (asyncio) or lifts its cancel scope's deadline (trio), so
    nothing fires and the watcher's task is not woken; the next request arms it again.
    On virtual time (asyncio on looptime, trio's MockClock; uvloop's clock cannot be
    virtual): on the wall clock a loaded machine answered later than the 20 ms RTO, and
    the read was retransmitted."""
    run_on_virtual_time(_answered_requests_do_not_wake_the_deadline_watcher, backend)


async def _answered_requests_do_not_wake_the_deadline_watcher() -> None:
    async with (
        udp_responder() as responder,
        session_for(responder, retries=2, timeout=1) as session,
    ):
        watcher = session._watcher
        await session.request(0x01, 0x01, read_params(0), idempotent=True)  # RTT measured
        await anyio.sleep(0.2)  # past its first wait (1/7 of the timeout: no RTO yet)
        assert watcher.disarms
        passes = watcher.passes
        for word in range(1, 6):
            response = await session.request(0x01, 0x01, read_params(word), idempotent=True)
            assert response.data == word_data(responder.received[-1])
            assert watcher.at == math.inf and watcher.timer is None  # (disarmed)
            await anyio.sleep(0.05)
        assert session.stats.retries == 0
        assert len(responder.received) == 6
        assert watcher.passes == passes


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_requests_back_to_back_keep_one_watcher_timer(backend: str) -> None:
    """After a paced phase (the timer cancelled as each reply leaves no deadline), requests
    sent back to back come while the cancelled timer would still be pending: the session
    stops cancelling, and one timer serves many requests again (a timer per request would
    cost more than the one firing). On virtual time, as above."""
    run_on_virtual_time(_requests_back_to_back_keep_one_watcher_timer, backend)


async def _requests_back_to_back_keep_one_watcher_timer() -> None:
    async with (
        udp_responder() as responder,
        session_for(responder, retries=2, timeout=1) as session,
    ):
        watcher = session._watcher
        for pause in (0.2, 0.05):  # (the first wait is 1/7 of the timeout: no RTO yet)
            await session.request(0x01, 0x01, read_params(0), idempotent=True)
            await anyio.sleep(pause)
        assert watcher.disarms and watcher.at == math.inf
        for word in range(5):
            await session.request(0x01, 0x01, read_params(word), idempotent=True)
        assert not watcher.disarms
        assert watcher.at != math.inf  # (one timer armed, for the first of them)
        assert session.stats.retries == 0
