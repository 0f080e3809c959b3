"""Session over real loopback FINS/TCP against an in-test server (asyncio and trio)."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import socket
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import anyio
import pytest
from anyio.abc import SocketAttribute, SocketStream, TaskStatus

from aiofins.protocol.errors import ConnectionLost, FinsTcpError, FinsTimeout, FrameError
from aiofins.protocol.header import FinsAddress
from aiofins.protocol.tcp import TcpDecoder, encode_message, encode_node_response
from aiofins.session import Session
from aiofins.session.background import Background
from aiofins.transport import TcpTransport

from ..virtual_time import on_virtual_time
from .loop_passes import counting_loop_passes
from .test_session_udp import read_params, reply, word_data

pytestmark = pytest.mark.anyio


@dataclass
class TcpPeer:
    """Behaviour of the in-test FINS/TCP server."""

    assign_node: int = 0x21
    server_node: int = 0x01
    refuse: int = 0  # FINS/TCP error code for the handshake reply
    confirmation: bool = False  # send command 6 before every reply
    byte_by_byte: bool = False  # dribble every message one byte at a time
    answer: Callable[[bytes], bytes | None] = lambda c: reply(c, 0, word_data(c))
    port: int = 0
    requested_nodes: list[int] = field(default_factory=list)
    frames: list[bytes] = field(default_factory=list)
    #: FINS frames completed by each receive of the stream (what one read brought).
    frames_per_read: list[int] = field(default_factory=list)
    streams: list[SocketStream] = field(default_factory=list)
    connections: int = 0
    error_notification: int = 0  # answer the next frame with command 3 instead
    delay: float = 0.0  # seconds before each answer (the stream is read again after it)
    #: While set to an event, a node address request is answered only once it is set.
    handshake_gate: anyio.Event | None = None
    serving: anyio.CancelScope | None = None
    served: anyio.Event | None = None  # set once the accept loop has ended
    listener: anyio.abc.Listener[anyio.abc.SocketStream] | None = None
    #: Sockets a test made on the server's connections (closed by stop()).
    duplicates: list[socket.socket] = field(default_factory=list)

    async def stop(self) -> None:
        """The PLC goes away: stop listening, drop every connection."""
        if self.serving is not None:
            self.serving.cancel()
            if self.served is not None:  # before the listener closes under its accept()
                await self.served.wait()
        for stream in self.streams:
            await stream.aclose()
        for sock in self.duplicates:
            sock.close()
        if self.listener is not None:
            await self.listener.aclose()

    async def drop(self) -> None:
        """Drop every connection and keep listening (the PLC resets its connections)."""
        streams, self.streams = self.streams, []
        for stream in streams:
            await stream.aclose()

    async def write(self, stream: SocketStream, data: bytes) -> None:
        if self.byte_by_byte:
            for i in range(len(data)):
                await stream.send(data[i : i + 1])
        else:
            await stream.send(data)

    async def handle(self, stream: SocketStream) -> None:
        self.connections += 1
        self.streams.append(stream)
        decoder = TcpDecoder()
        try:
            async with stream:
                while True:
                    messages = decoder.feed(await stream.receive())
                    self.frames_per_read.append(sum(m.command == 2 for m in messages))
                    for msg in messages:
                        await self.on_message(stream, msg.command, msg.payload)
        except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
            pass

    async def on_message(self, stream: SocketStream, command: int, payload: bytes) -> None:
        if command == 0:
            requested = int.from_bytes(payload, "big")
            self.requested_nodes.append(requested)
            if self.handshake_gate is not None:
                await self.handshake_gate.wait()
            node = requested or self.assign_node
            await self.write(stream, encode_node_response(node, self.server_node, self.refuse))
            if self.refuse:
                await stream.aclose()
        elif command == 2:
            self.frames.append(payload)
            if self.error_notification:
                await self.write(stream, encode_message(3, b"", self.error_notification))
                await stream.aclose()
                return
            answer = self.answer(payload)
            if answer is None:
                return
            if self.delay:
                await anyio.sleep(self.delay)
            if self.confirmation:
                await self.write(stream, encode_message(6, b""))
            await self.write(stream, encode_message(2, answer))


@asynccontextmanager
async def tcp_server(peer: TcpPeer) -> AsyncIterator[TcpPeer]:
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=peer.port)
    peer.port = listener.extra(SocketAttribute.local_port)
    peer.listener = listener
    async with anyio.create_task_group() as tg:
        # Its own scope: peer.stop() must not cancel the test's body (it once did, silently
        # skipping the rest of the test).
        serving = peer.serving = anyio.CancelScope()
        served = peer.served = anyio.Event()

        async def serve() -> None:
            try:
                with serving:
                    await listener.serve(peer.handle, tg)
            finally:
                served.set()

        tg.start_soon(serve)
        yield peer
        tg.cancel_scope.cancel()
    await peer.stop()


def tcp_session(peer: TcpPeer, node: int = 0, **options: object) -> Session:
    return Session(
        TcpTransport("127.0.0.1", peer.port, node=node, connect_timeout=2),
        source=FinsAddress(0, 0, 0),
        dest=FinsAddress(0, 1, 0),
        **options,  # type: ignore[arg-type]
    )


async def test_handshake_allocates_our_node_and_it_becomes_sa1() -> None:
    async with tcp_server(TcpPeer(assign_node=0x21)) as peer, tcp_session(peer) as session:
        transport = session.transport
        assert (transport.local_node, transport.remote_node) == (0x21, 0x01)
        assert peer.requested_nodes == [0]
        response = await session.request(0x01, 0x01, read_params(10, 2))
        assert response.data == bytes.fromhex("100A100B")
        frame = peer.frames[0]
        assert frame[:9] == bytes((0x80, 0, 2, 0, 1, 0, 0, 0x21, 0))
        assert session.source == FinsAddress(0, 0x21, 0)


async def test_fixed_client_node_is_requested() -> None:
    async with tcp_server(TcpPeer()) as peer, tcp_session(peer, node=7) as session:
        assert peer.requested_nodes == [7]
        assert session.transport.local_node == 7
        await session.request(0x01, 0x01, read_params(0))
        assert peer.frames[0][7] == 7


async def test_refused_handshake_raises_fins_tcp_error() -> None:
    async with tcp_server(TcpPeer(refuse=0x21)) as peer:
        with pytest.raises(FinsTcpError) as info:
            async with tcp_session(peer):
                pass
        assert info.value.tcp_error_code == 0x21
        assert "already connected" in str(info.value)


async def test_split_frames_and_confirmations_are_handled() -> None:
    peer_cfg = TcpPeer(byte_by_byte=True, confirmation=True)
    async with tcp_server(peer_cfg) as peer, tcp_session(peer) as session:
        results = []
        async with anyio.create_task_group() as tg:

            async def one(word: int) -> None:
                results.append((word, (await session.request(0x01, 0x01, read_params(word))).data))

            for word in range(8):
                tg.start_soon(one, word)
        assert sorted(results) == [(w, (0x1000 | w).to_bytes(2, "big")) for w in range(8)]
        assert session.stats.malformed == 0


async def test_error_notification_fails_in_flight_with_fins_tcp_error() -> None:
    async with tcp_server(TcpPeer(error_notification=0x03)) as peer, tcp_session(peer) as s:
        with pytest.raises(FinsTcpError) as info:
            await s.request(0x01, 0x01, read_params(0))
        assert info.value.tcp_error_code == 0x03
        # The server closed the connection: the next call reconnects.
        peer.error_notification = 0
        assert (await s.request(0x01, 0x01, read_params(1))).data == bytes.fromhex("1001")
        assert peer.connections == 2 and s.stats.connects == 2


async def test_server_restart_mid_flight_then_next_call_reconnects() -> None:
    first = TcpPeer(answer=lambda c: None)  # never answers: the request stays in flight
    async with tcp_server(first) as peer:
        port = peer.port
        session = tcp_session(peer, timeout=5, reconnect_backoff=(0.01, 0.1))
        async with session:
            outcome: list[BaseException] = []

            async def in_flight() -> None:
                try:
                    await session.request(0x01, 0x01, read_params(0))
                except ConnectionLost as exc:
                    outcome.append(exc)

            async with anyio.create_task_group() as tg:
                tg.start_soon(in_flight)
                await anyio.wait_all_tasks_blocked()
                while not peer.frames:
                    await anyio.wait_all_tasks_blocked()
                    await anyio.sleep(0)
                await peer.stop()  # the PLC goes away
            assert len(outcome) == 1 and "closed" in str(outcome[0])
            assert session.stats.disconnects == 1
            async with tcp_server(TcpPeer(port=port, assign_node=0x33)):
                with anyio.fail_after(3):
                    r = await session.request(0x01, 0x01, read_params(2))
                assert r.data == bytes.fromhex("1002")
                assert session.source.node == 0x33
                assert session.stats.connects == 2
                assert session.stats.disconnects == 1 and session.stats.connect_failures == 0


@on_virtual_time
async def test_calls_fail_fast_during_the_reconnect_backoff() -> None:
    """A call used to sleep out the reconnect backoff (doubling to 5 s) before trying,
    whatever its timeout: a poller's scans stalled through an outage. Now a call in the
    backoff fails at once, and the first call after it tries again. On virtual time
    (uvloop's clock cannot be virtual): "at once" is exactly no time."""
    from aiofins.simulator import VirtualPLC, run_simulator

    async def plc(
        port: int, stop: anyio.Event, *, task_status: TaskStatus[int] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        async with run_simulator(VirtualPLC(), tcp=("127.0.0.1", port)) as sim:
            task_status.started(sim.tcp_port)
            await stop.wait()

    async with anyio.create_task_group() as tg:
        stop = anyio.Event()
        port = await tg.start(plc, 0, stop)
        session = Session(
            TcpTransport("127.0.0.1", port, connect_timeout=2),
            source=FinsAddress(0, 0, 0),
            dest=FinsAddress(0, 1, 0),
            timeout=0.3,
            reconnect_backoff=(0.3, 1.0),
        )
        async with session:
            await session.request(0x01, 0x01, read_params(0))
            stop.set()  # the PLC goes away
            with anyio.fail_after(5):
                while session.stats.disconnects == 0:
                    await anyio.sleep(0.01)
            with pytest.raises(ConnectionLost, match="cannot connect"):
                await session.request(0x01, 0x01, read_params(0))  # refused: backoff 0.3 s
            start = anyio.current_time()
            for _ in range(3):
                with pytest.raises(ConnectionLost, match=r"the next one in 0\.[0-3]\d s"):
                    await session.request(0x01, 0x01, read_params(0))
            assert anyio.current_time() - start == 0.0  # no sleeping through the backoff
            assert session.stats.connect_failures == 1  # and no attempts meanwhile
            await tg.start(plc, port, anyio.Event())  # the PLC is back
            with anyio.fail_after(5):
                while True:
                    try:
                        r = await session.request(0x01, 0x01, read_params(3))
                        break
                    except ConnectionLost:
                        await anyio.sleep(0.05)
            assert r.data == b"\x00\x00"
            assert session.stats.connect_failures == 1 and session.stats.connects == 2
        tg.cancel_scope.cancel()


async def test_a_loop_of_calls_failing_at_once_lets_other_tasks_run() -> None:
    """Calls that fail without waiting (the reconnect backoff; a send on a socket that can no
    longer send, before the transport has been told) yield once each: a caller retrying in
    a loop with no sleep of its own does not starve the other tasks, and once the transport
    has run, the next call connects again."""
    async with tcp_server(TcpPeer()) as peer, tcp_session(peer, timeout=2) as session:
        await session.request(0x01, 0x01, read_params(0))
        async with counting_loop_passes() as passes:
            # Our own end can no longer send: every send fails at once.
            transport = session.transport
            assert isinstance(transport, TcpTransport)
            own = transport._raw or transport._aio.sock  # type: ignore[union-attr]
            assert own is not None
            own.shutdown(socket.SHUT_WR)
            outcomes: list[str] = []
            with anyio.fail_after(5):
                for _ in range(50):
                    try:
                        await session.request(0x01, 0x01, read_params(1))
                        outcomes.append("ok")
                    except ConnectionLost:
                        outcomes.append("lost")
        lost = outcomes.count("lost")
        assert lost and passes.count >= lost, (passes.count, outcomes)
        assert outcomes[-1] == "ok" and peer.connections == 2, outcomes  # connected again


async def test_a_loop_of_calls_in_the_reconnect_backoff_lets_other_tasks_run() -> None:
    async with tcp_server(TcpPeer()) as peer:
        # A backoff of 60 s: the 40 calls below fall inside it however loaded the machine.
        session = tcp_session(peer, reconnect_backoff=(60.0, 60.0))
        async with session:
            await session.request(0x01, 0x01, read_params(0))
            await peer.stop()  # gone: connections refused from now on
            with anyio.fail_after(5):
                while session.stats.disconnects == 0:
                    await anyio.sleep(0.01)
            with pytest.raises(ConnectionLost, match="cannot connect"):
                await session.request(0x01, 0x01, read_params(0))  # refused: backoff 60 s
            async with counting_loop_passes() as passes:
                for _ in range(20):  # a caller retrying with no pause of its own
                    with pytest.raises(ConnectionLost, match="reconnect backoff"):
                        await session.request(0x01, 0x01, read_params(0))
                    with pytest.raises(ConnectionLost, match="reconnect backoff"):
                        await session.request_many([(0x01, 0x01, read_params(0))] * 2)
            assert passes.count >= 38, passes.count


async def test_connect_refused_raises_connection_lost() -> None:
    async with tcp_server(TcpPeer()) as peer:
        port = peer.port
    session = Session(
        TcpTransport("127.0.0.1", port, connect_timeout=1),
        source=FinsAddress(0, 0, 0),
        dest=FinsAddress(0, 1, 0),
    )
    with pytest.raises(ConnectionLost):
        async with session:
            pass
    assert session.stats.connect_failures == 1 and session.stats.connects == 0


async def test_timeout_over_tcp() -> None:
    async with (
        tcp_server(TcpPeer(answer=lambda c: None)) as peer,
        tcp_session(peer, timeout=0.05) as session,
    ):
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read_params(0))
        assert session.stats.timeouts == 1


async def test_a_slow_reply_over_tcp_is_awaited_not_retransmitted_after_the_rto(
    anyio_backend: object,
) -> None:
    """A stream loses nothing: once the round trip is measured (RTO at its 20 ms floor), a
    reply 60 ms late is waited for on the call's own schedule (1/7 of timeout=10 first: a
    loaded machine's reply is not later than that), not sent again after the RTO."""
    peer = TcpPeer()
    async with tcp_server(peer), tcp_session(peer, retries=2, timeout=10) as session:
        await session.request(0x01, 0x01, read_params(0), idempotent=True)  # RTT measured
        peer.delay = 0.06
        slow = await session.request(0x01, 0x01, read_params(1), idempotent=True)
        peer.delay = 0.0
        # Read by the peer after anything sent before it: a duplicate would be in frames.
        await session.request(0x01, 0x01, read_params(2), idempotent=True)
        assert slow.data == word_data(peer.frames[1])
        assert [f[13:15] for f in peer.frames] == [b"\x00\x00", b"\x00\x01", b"\x00\x02"]
        assert session.stats.retries == 0


def sid_order(frames: list[bytes]) -> list[int]:
    """The SIDs of the frames the peer received, in the order it received them."""
    return [frame[9] for frame in frames]


async def test_concurrent_requests_arrive_whole_and_in_sid_order() -> None:
    """50 callers in one event-loop step: every frame intact, in the order of its SID.

    Under asyncio (and uvloop) the transport writes a frame at once when it is the only one in
    flight and gathers the frames sent while others are in flight into one write per step;
    the order must survive that. (How the peer's reads group the bytes is up to the kernel,
    so the gathering itself is shown by the request_many test below.)
    """
    async with tcp_server(TcpPeer()) as peer, tcp_session(peer, max_in_flight=50) as session:
        results: dict[int, bytes] = {}

        async def one(word: int) -> None:
            results[word] = (await session.request(0x01, 0x01, read_params(word))).data

        async with anyio.create_task_group() as tg:
            for word in range(50):
                tg.start_soon(one, word)
        assert results == {w: (0x1000 | w).to_bytes(2, "big") for w in range(50)}
        assert sid_order(peer.frames) == sorted(sid_order(peer.frames))
        assert sorted(int.from_bytes(f[13:15], "big") for f in peer.frames) == list(range(50))


async def test_request_many_over_tcp_writes_each_step_once(anyio_backend: object) -> None:
    """A batch's window goes out as one write; replies in any grouping complete it."""
    async with tcp_server(TcpPeer()) as peer, tcp_session(peer, max_in_flight=20) as session:
        commands = [(0x01, 0x01, read_params(w)) for w in range(500)]
        results = await session.request_many(commands, window=20)
        assert [r.data for r in results] == [(0x1000 | w).to_bytes(2, "big") for w in range(500)]
        assert len(peer.frames) == 500
        assert session.stats.in_flight == 0 and session.stats.completed == 500
        if anyio_backend != "trio":  # the first window: one write of 20 frames
            assert peer.frames_per_read[1] == 20, peer.frames_per_read


async def test_gathering_can_be_turned_off(anyio_backend: object) -> None:
    """``gather_writes=False``: every frame on its own write, the same results."""
    async with tcp_server(TcpPeer()) as peer:
        session = Session(
            TcpTransport("127.0.0.1", peer.port, connect_timeout=2, gather_writes=False),
            source=FinsAddress(0, 0, 0),
            dest=FinsAddress(0, 1, 0),
            max_in_flight=20,
        )
        async with session:
            commands = [(0x01, 0x01, read_params(w)) for w in range(100)]
            results = await session.request_many(commands, window=20)
            assert [r.data for r in results] == [
                (0x1000 | w).to_bytes(2, "big") for w in range(100)
            ]
            assert sid_order(peer.frames[:20]) == sorted(sid_order(peer.frames[:20]))


class _Sink:
    """A sink for a transport opened on its own (nothing is requested here)."""

    def frame_received(self, frame: bytes, _addr: object = None, /) -> None:
        pass

    def frame_dropped(self, reason: str) -> None:
        pass

    def connection_lost(self, exc: BaseException | None) -> None:
        pass


@pytest.mark.parametrize(
    "anyio_backend", ["asyncio", ("asyncio", {"use_uvloop": True})], ids=["asyncio", "uvloop"]
)
async def test_a_connect_cancelled_at_any_step_logs_no_unretrieved_error(
    anyio_backend: object,
) -> None:
    """A connect cancelled while asyncio makes its transport (after ``connection_made``)
    closed the transport, whose ``connection_lost`` then failed the handshake future nobody
    awaited any more: asyncio logged "Future exception was never retrieved" (the session
    cancels its connection attempt whenever it closes during one). Cancelled after each
    number of event-loop steps in turn, so one of them lands in that window."""
    loop = asyncio.get_running_loop()  # asyncio futures only: no trio variant
    logged: list[dict[str, object]] = []
    handler = loop.get_exception_handler()
    loop.set_exception_handler(lambda _, context: logged.append(context))
    try:
        async with tcp_server(TcpPeer()) as peer, anyio.create_task_group() as tg:
            for steps in [*range(16)] * 4:
                transport = TcpTransport("127.0.0.1", peer.port, connect_timeout=2)
                task = asyncio.ensure_future(transport.open(_Sink(), Background(tg)))
                for _ in range(steps):  # event-loop steps, not time
                    await asyncio.sleep(0)
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
                await transport.aclose()
                for _ in range(3):  # the transport's connection_lost runs in these steps
                    await asyncio.sleep(0)
            del task
            gc.collect()
    finally:
        loop.set_exception_handler(handler)
    assert [context.get("message") for context in logged] == []


def _traceback_length(exc: BaseException) -> int:
    n, tb = 0, exc.__traceback__
    while tb is not None:
        n, tb = n + 1, tb.tb_next
    return n


async def test_requests_failed_by_one_lost_connection_each_get_its_traceback_once() -> None:
    """The requests in flight when the connection goes get its one error: under trio each
    re-raised it as is, growing its traceback by every earlier request's frames."""
    async with (
        tcp_server(TcpPeer(answer=lambda c: None)) as peer,
        tcp_session(peer, max_in_flight=20) as session,
    ):
        lengths: list[int] = []

        async def call() -> None:
            try:
                await session.request(0x01, 0x01, read_params(0), timeout=5)
            except ConnectionLost as exc:
                lengths.append(_traceback_length(exc))  # as each caller sees it

        with anyio.fail_after(5):
            async with anyio.create_task_group() as tg:
                for _ in range(20):
                    tg.start_soon(call)
                await anyio.wait_all_tasks_blocked()
                await peer.drop()
        assert len(lengths) == 20 and len(set(lengths)) == 1, lengths


async def test_callers_queued_for_a_slot_when_the_session_closes_get_its_traceback_once() -> None:
    async with tcp_server(TcpPeer(answer=lambda c: None)) as peer:
        lengths: dict[int, list[int]] = {}  # the error (its id) -> each caller's length
        async with tcp_session(peer, max_in_flight=1) as session:

            async def call() -> None:
                try:
                    await session.request(0x01, 0x01, read_params(0), timeout=5)
                except ConnectionLost as exc:
                    lengths.setdefault(id(exc), []).append(_traceback_length(exc))

            with anyio.fail_after(5):
                async with anyio.create_task_group() as tg:
                    for _ in range(20):
                        tg.start_soon(call)
                    await anyio.wait_all_tasks_blocked()
                    await session.aclose()  # 1 request in flight, 19 queued for its slot
        # The one in flight gets the link's error, the 19 queued one error of their own
        # (their callers finish in any order under trio): each as it is, not grown by
        # another caller's frames.
        assert sorted(len(each) for each in lengths.values()) == [1, 19], lengths
        assert all(len(set(each)) == 1 for each in lengths.values()), lengths


@dataclass
class StalledPlc:
    """A FINS/TCP peer that answers the node-address handshake, then reads nothing until
    ``reading`` is set (its 4 KB receive buffer fills), then answers every read or write."""

    reading: anyio.Event = field(default_factory=anyio.Event)
    received: list[bytes] = field(default_factory=list)  # the frames decoded, all connections
    broken: list[FrameError] = field(default_factory=list)  # the stream turned to garbage

    async def handle(self, stream: SocketStream) -> None:
        decoder = TcpDecoder()
        async with stream:
            try:
                for msg in decoder.feed(await stream.receive()):
                    if msg.command == 0:
                        await stream.send(encode_node_response(0x21, 0x01))
                await self.reading.wait()
                while True:
                    for msg in decoder.feed(await stream.receive()):
                        if msg.command == 2:
                            self.received.append(msg.payload)
                            answer = reply(msg.payload, 0, word_data(msg.payload))
                            await stream.send(encode_message(2, answer))
            except FrameError as exc:
                self.broken.append(exc)
            except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
                pass


#: A 994-word write (0102): about 2 KB a frame, to fill socket buffers with few requests.
BIG_WRITE = bytes.fromhex("8200000003E2") + bytes(1988)


@asynccontextmanager
async def stalled_plc_session(**options: object) -> AsyncIterator[tuple[StalledPlc, Session]]:
    """A :class:`StalledPlc` and a session to it whose socket sends through a 4 KB buffer."""
    plc = StalledPlc()
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
    listener_sock = listener.extra(SocketAttribute.raw_socket)
    listener_sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # accepted inherit it
    port = listener.extra(SocketAttribute.local_port)
    async with anyio.create_task_group() as server:
        server.start_soon(listener.serve, plc.handle)
        session = Session(
            TcpTransport("127.0.0.1", port, gather_writes=False),
            source=FinsAddress(0, 0, 0),
            dest=FinsAddress(0, 1, 0),
            **options,  # type: ignore[arg-type]
        )
        async with session:
            transport = session.transport
            assert isinstance(transport, TcpTransport)
            own = transport._raw or transport._aio.sock  # type: ignore[union-attr]
            assert own is not None
            own.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
            yield plc, session
        server.cancel_scope.cancel()
    await listener.aclose()


async def test_a_send_cancelled_part_way_through_a_frame_ends_the_connection(
    anyio_backend: object,
) -> None:
    """The PLC stops reading; requests fill the socket's send buffer until one frame goes out
    only in part and its sender waits for room. Cancelled there, the rest of that frame was
    never written and the next frame followed the part on the same stream: the PLC read
    garbage from then on. The connection must end instead; the next call reconnects."""
    async with stalled_plc_session(max_in_flight=200, timeout=30) as (plc, session):
        with anyio.move_on_after(10) as scope:  # a bound: the writers block well before
            async with anyio.create_task_group() as tg:
                for _ in range(200):
                    tg.start_soon(session.request, 0x01, 0x02, BIG_WRITE)
                await anyio.wait_all_tasks_blocked()  # the buffer full, writers waiting
                tg.cancel_scope.cancel()
        assert not scope.cancelled_caught
        plc.reading.set()
        with anyio.fail_after(5):
            response = await session.request(0x01, 0x01, read_params(7))
        assert response.data == (0x1007).to_bytes(2, "big")
        assert plc.received[-1][10:] == bytes.fromhex("0101") + read_params(7)
        assert all(frame[10:12] == b"\x01\x02" for frame in plc.received[:-1])
        assert plc.broken == []


@on_virtual_time  # "within 3 s" is the calls' bound, exact on virtual time; on the wall
# clock a loaded machine could take longer (uvloop: its clock cannot be virtual)
async def test_a_send_to_a_plc_that_stopped_reading_is_bounded_by_the_timeout() -> None:
    """The PLC stops reading: under trio a FINS/TCP send then waits for room in the socket,
    and it waited with no bound but the caller's own cancellation. Every call ends within its
    timeout instead (FinsTimeout), a frame left half-written ends the connection, and once
    the PLC reads again the next call works."""
    async with stalled_plc_session(max_in_flight=100, timeout=0.5) as (plc, session):
        outcomes: list[str] = []

        async def call() -> None:
            try:
                await session.request(0x01, 0x02, BIG_WRITE)
                outcomes.append("ok")
            except FinsTimeout:
                outcomes.append("timeout")
            except ConnectionLost:
                outcomes.append("lost")  # its connection ended under it

        with anyio.fail_after(3):  # each call: 0.5 s; none may wait for the PLC
            async with anyio.create_task_group() as tg:
                for _ in range(100):
                    tg.start_soon(call)
        assert len(outcomes) == 100 and "ok" not in outcomes, outcomes
        assert outcomes.count("timeout") >= 50, outcomes
        plc.reading.set()
        with anyio.fail_after(5):
            while True:  # the connection may have ended: the next call reconnects
                try:
                    response = await session.request(0x01, 0x01, read_params(7))
                    break
                except ConnectionLost:
                    await anyio.sleep(0.05)
        assert response.data == (0x1007).to_bytes(2, "big")
