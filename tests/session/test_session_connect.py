"""A call waits for a (re)connection at most its own timeout, over real loopback FINS/TCP.

The connection attempt itself keeps its own bound (``connect_timeout``, 5 s here) and is
shared: callers that give up leave it running for the next call. Two ways a PLC keeps a
connect hanging: it accepts and never answers the FINS/TCP node address request ("silent"),
or its SYNs go unanswered ("black-hole": a listening socket whose accept queue is full).
"""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager

import anyio
import pytest

from aiofins.protocol.errors import ConnectionLost, FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Response, Session
from aiofins.transport import TcpTransport

from ..virtual_time import on_virtual_time
from .test_session_tcp import TcpPeer, tcp_server
from .test_session_udp import read_params

pytestmark = pytest.mark.anyio

#: The transport's own bound on a connection attempt: far above every call's timeout here.
CONNECT_TIMEOUT = 5.0
STILL_CONNECTING = r"no connection to tcp://127\.0\.0\.1:\d+ within 0\.3 s: a connection attempt"


@contextmanager
def black_hole(port: int) -> Iterator[None]:
    """Listen on ``port`` with an accept queue of one, filled and never accepted: the kernel
    drops further SYNs, so a connect hangs as towards a host that drops packets. Skips the
    test where a full queue does not do that."""
    with socket.socket() as listener, socket.socket() as filler:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", port))
        listener.listen(0)
        filler.settimeout(2)
        filler.connect(("127.0.0.1", port))  # takes the only place in the queue
        with socket.socket() as probe:
            probe.settimeout(0.2)
            try:
                probe.connect(("127.0.0.1", port))
            except TimeoutError:
                pass
            else:
                pytest.skip("a full accept queue does not black-hole connects on this system")
        yield


@asynccontextmanager
async def connected_then_stuck(
    kind: str, **options: object
) -> AsyncIterator[tuple[Session, TcpPeer]]:
    """A session that connected, lost its connection, and whose next connect hangs."""
    async with tcp_server(TcpPeer()) as peer:
        session = Session(
            TcpTransport("127.0.0.1", peer.port, connect_timeout=CONNECT_TIMEOUT),
            source=FinsAddress(0, 0, 0),
            dest=FinsAddress(0, 1, 0),
            **options,  # type: ignore[arg-type]
        )
        async with session:
            await session.request(0x01, 0x01, read_params(0))
            if kind == "silent":
                peer.handshake_gate = anyio.Event()
                await peer.drop()
            else:
                await peer.stop()
            with anyio.fail_after(5):
                while session.transport.is_open:  # the session sees the connection go
                    await anyio.sleep(0.01)
            if kind == "silent":
                yield session, peer
            else:
                with black_hole(peer.port):
                    yield session, peer


@pytest.mark.parametrize("kind", ["silent", "black-hole"])
@on_virtual_time
async def test_a_call_waits_for_a_connection_at_most_its_timeout(kind: str) -> None:
    """A call with timeout=0.3 used to wait out the whole connect timeout (5 s). On virtual
    time (uvloop's clock cannot be virtual): each call ends at exactly its timeout."""
    async with connected_then_stuck(kind) as (session, peer):
        with anyio.fail_after(1.5), pytest.raises(FinsTimeout, match=STILL_CONNECTING):
            await session.request(0x01, 0x01, read_params(0), timeout=0.3)
        with anyio.fail_after(1.5), pytest.raises(FinsTimeout, match=STILL_CONNECTING):
            await session.request_many([(0x01, 0x01, read_params(0))] * 3, timeout=0.3)
        # A read's timeout bounds the whole call, its wait for the connection included.
        start = anyio.current_time()
        with anyio.fail_after(1.5), pytest.raises(FinsTimeout, match=STILL_CONNECTING):
            await session.request(0x01, 0x01, read_params(0), timeout=0.3, idempotent=True)
        assert anyio.current_time() - start == pytest.approx(0.3, abs=1e-6)
        assert session.stats.retries == 0
        assert session.stats.connect_failures == 0  # the one attempt is still in progress
        if kind == "silent":
            assert peer.connections == 2  # the first connection, then one attempt for all


async def test_callers_with_different_timeouts_share_one_attempt() -> None:
    async with connected_then_stuck("silent") as (session, peer):
        gate = peer.handshake_gate
        assert gate is not None
        outcome: dict[str, Response | BaseException] = {}

        async def call(name: str, timeout: float) -> None:
            try:
                outcome[name] = await session.request(0x01, 0x01, read_params(2), timeout=timeout)
            except FinsTimeout as exc:
                outcome[name] = exc
                gate.set()  # the server answers the handshake only now

        with anyio.fail_after(3):
            async with anyio.create_task_group() as tg:
                tg.start_soon(call, "short", 0.3)
                tg.start_soon(call, "long", 4.0)
        short, long = outcome["short"], outcome["long"]
        assert isinstance(short, FinsTimeout) and "still in progress" in str(short)
        assert isinstance(long, Response) and long.data == bytes.fromhex("1002")
        assert peer.connections == 2 and session.stats.connects == 2
        assert session.stats.connect_failures == 0


async def test_an_attempt_a_call_gave_up_on_serves_the_next_call() -> None:
    async with connected_then_stuck("silent") as (session, peer):
        with anyio.fail_after(1.5), pytest.raises(FinsTimeout, match=STILL_CONNECTING):
            await session.request(0x01, 0x01, read_params(0), timeout=0.3)
        assert peer.handshake_gate is not None
        peer.handshake_gate.set()  # the server finally answers
        with anyio.fail_after(3):
            response = await session.request(0x01, 0x01, read_params(3), timeout=2)
        assert response.data == bytes.fromhex("1003")
        assert peer.connections == 2  # no new connection: the abandoned attempt completed
        assert session.stats.connects == 2 and session.stats.connect_failures == 0


@pytest.mark.parametrize("kind", ["silent", "black-hole"])
async def test_closing_while_connecting_fails_the_waiters_at_once(kind: str) -> None:
    async with connected_then_stuck(kind) as (session, _):
        outcome: list[BaseException] = []

        async def waiter() -> None:
            try:
                await session.request(0x01, 0x01, read_params(0), timeout=10)
            except ConnectionLost as exc:
                outcome.append(exc)

        with anyio.fail_after(1.5):  # not the connect timeout (5 s), nor the call's (10 s)
            async with anyio.create_task_group() as tg:
                tg.start_soon(waiter)
                await anyio.wait_all_tasks_blocked()
                await session.aclose()
        assert len(outcome) == 1 and "closed while connecting" in str(outcome[0])


@on_virtual_time
async def test_opening_a_session_is_still_bounded_by_the_connect_timeout() -> None:
    """``async with Session`` connects eagerly, bounded by connect_timeout, not by the
    request timeout. On virtual time (uvloop's clock cannot be virtual): exactly 0.5 s."""
    peer = TcpPeer(handshake_gate=anyio.Event())
    async with tcp_server(peer):
        session = Session(
            TcpTransport("127.0.0.1", peer.port, connect_timeout=0.5),
            source=FinsAddress(0, 0, 0),
            dest=FinsAddress(0, 1, 0),
            timeout=0.05,
        )
        start = anyio.current_time()
        with anyio.fail_after(3), pytest.raises(ConnectionLost, match=r"within 0\.5 s"):
            async with session:
                pass
        assert anyio.current_time() - start == pytest.approx(0.5, abs=1e-6)
        assert session.stats.connect_failures == 1
