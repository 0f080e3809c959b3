"""The in-memory network (aiofins/memnet.py): addresses, datagrams, byte streams, the fault
hook, bounds. Times are asserted exactly under trio's MockClock; under the other backends
only what arrives, in which order."""

from __future__ import annotations

import contextvars
from collections.abc import Awaitable, Callable, Sequence

import anyio
import pytest
import trio
import trio.testing

from aiofins.memnet import MemoryNetwork, MemoryStream, Packet

from .virtual_time import VIRTUAL_BACKENDS, run_on_virtual_time

pytestmark = pytest.mark.anyio

A, B = ("10.0.0.1", 5000), ("10.0.0.2", 9600)


def on_virtual_time(main: Callable[[], Awaitable[None]]) -> None:
    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))


async def test_a_datagram_arrives_with_its_sender_s_address(anyio_backend: object) -> None:
    async with MemoryNetwork() as net:
        a = net.datagram_socket(*A)
        b = net.datagram_socket(*B)
        a.sendto(b"\x01\x02", B)
        with pytest.raises(BlockingIOError):
            b.recv(100)  # not inside the send: on the delivery task's next pass
        assert await b.receive() == (b"\x01\x02", A)
        await b.send_to(b"reply", *A)
        assert await a.receive() == (b"reply", B)
        assert net.stats.sent == net.stats.delivered == 2


def test_a_network_that_is_not_running_refuses_sockets() -> None:
    net = MemoryNetwork()
    with pytest.raises(RuntimeError, match="async with MemoryNetwork"):
        net.datagram_socket()
    with pytest.raises(RuntimeError, match="async with MemoryNetwork"):
        net.listen("10.0.0.1", 1)


async def test_ephemeral_ports_come_in_order_and_an_address_is_bound_once(
    anyio_backend: object,
) -> None:
    async with MemoryNetwork(default_host="10.0.0.9") as net:
        first = net.datagram_socket()
        second = net.datagram_socket("10.0.0.1")
        assert first.getsockname() == ("0.0.0.0", 49152)
        assert second.getsockname() == ("10.0.0.1", 49153)
        with pytest.raises(OSError, match="in use"):
            net.datagram_socket("10.0.0.1", 49153)
        b = net.datagram_socket(*B)
        first.sendto(b"x", B)  # a socket bound to any address sends from the default host
        assert await b.receive() == (b"x", ("10.0.0.9", 49152))


async def test_a_connected_socket_takes_only_its_peer_s_datagrams_and_hears_of_a_closed_port(
    anyio_backend: object,
) -> None:
    async with MemoryNetwork() as net:
        client = net.datagram_socket(*A, remote=B)
        other = net.datagram_socket("10.0.0.3", 7)
        other.sendto(b"stray", A)
        client.send(b"to nobody")  # nothing bound at B: port unreachable
        await anyio.wait_all_tasks_blocked()
        with pytest.raises(ConnectionRefusedError):
            client.recv(100)
        with pytest.raises(BlockingIOError):
            client.recv(100)  # the stray datagram was not taken
        assert (net.stats.filtered, net.stats.unreachable) == (1, 1)
        assert client.getpeername() == B


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_the_fault_hook_drops_duplicates_and_reorders(backend: str) -> None:
    """(On virtual time: on the wall clock, time passing between two sends under load would
    decide the order of delays this short.)"""
    seen: list[Packet] = []
    got: list[tuple[float, bytes]] = []

    def fate(packet: Packet) -> Sequence[float]:
        seen.append(packet)
        return {b"drop": [], b"twice": [0.0, 0.002], b"late": [0.004]}.get(packet.data, [0.0])

    async def main() -> None:
        async with MemoryNetwork(fate=fate) as net:
            a, b = net.datagram_socket(*A), net.datagram_socket(*B)
            for data in (b"drop", b"late", b"twice", b"plain"):
                a.sendto(data, B)
            for _ in range(4):
                data, _source = await b.receive()
                got.append((round(anyio.current_time(), 6), data))
            assert (net.stats.dropped, net.stats.duplicated, net.stats.delivered) == (1, 1, 4)

    run_on_virtual_time(main, backend)
    assert got == [(0.0, b"twice"), (0.0, b"plain"), (0.002, b"twice"), (0.004, b"late")]
    assert [(p.kind, p.source, p.dest, p.data, p.number) for p in seen] == [
        ("datagram", A, B, b"drop", 1),
        ("datagram", A, B, b"late", 2),
        ("datagram", A, B, b"twice", 3),
        ("datagram", A, B, b"plain", 4),
    ]


def test_delays_are_exact_on_virtual_time() -> None:
    arrived: list[tuple[float, bytes]] = []

    async def main() -> None:
        async with MemoryNetwork(fate=lambda p: [float(p.data[0])]) as net:
            a, b = net.datagram_socket(*A), net.datagram_socket(*B)
            b.on_readable = lambda: arrived.append((trio.current_time(), b.recv(10)))
            for delay in (3, 1, 2):
                a.sendto(bytes([delay]), B)
            await trio.sleep(10)

    on_virtual_time(main)
    assert arrived == [(1.0, b"\x01"), (2.0, b"\x02"), (3.0, b"\x03")]


async def test_nothing_raised_by_the_hook_or_a_callback_escapes_a_delivery(
    anyio_backend: object,
) -> None:
    def fate(packet: Packet) -> Sequence[float]:
        if packet.data == b"bad":
            raise RuntimeError("a broken fault schedule")
        return [0.0]

    def callback() -> None:
        raise RuntimeError("a broken reader")

    async with MemoryNetwork(fate=fate) as net:
        a, b = net.datagram_socket(*A), net.datagram_socket(*B)
        b.on_readable = callback
        a.sendto(b"bad", B)  # dropped, counted
        a.sendto(b"good", B)
        assert await b.receive() == (b"good", A)
        assert (net.stats.hook_errors, net.stats.dropped, net.stats.callback_errors) == (1, 1, 1)


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_every_queue_is_bounded(backend: str) -> None:
    async def main() -> None:
        async with MemoryNetwork(rcvbuf=3, max_queued=5, fate=lambda p: [1.0]) as net:
            a, b = net.datagram_socket(*A), net.datagram_socket(*B)
            for i in range(8):  # 5 on the wire, 3 beyond its bound
                a.sendto(bytes([i]), B)
            assert net.stats.overflows == 3
            net.fate = None
            got = [(await b.receive())[0] for _ in range(3)]  # 3 taken, 2 beyond the socket's
            assert got == [b"\x00", b"\x01", b"\x02"]
            assert net.stats.overflows == 3 + 2
            a.sendto(b"now", B)  # (the hook changed: no delay)
            assert await b.receive() == (b"now", A)

    run_on_virtual_time(main, backend)


# -- streams --------------------------------------------------------------------------------


async def connected(net: MemoryNetwork) -> tuple[MemoryStream, MemoryStream]:
    listener = net.listen(*B)
    client = await net.connect(*B, local_host=A[0])
    server = await listener.accept()
    return client, server


async def test_a_connection_carries_bytes_both_ways_then_its_end(anyio_backend: object) -> None:
    async with MemoryNetwork() as net:
        with pytest.raises(ConnectionRefusedError):
            await net.connect(*B)
        client, server = await connected(net)
        assert client.remote == B and server.remote == client.local
        assert client.local == ("10.0.0.1", 49153)  # (49152 went to the refused attempt)
        await client.send(b"hello")
        assert await server.receive() == b"hello"
        await server.send(b"world")
        await server.aclose()
        assert await client.receive() == b"world"
        with pytest.raises(anyio.EndOfStream):
            await client.receive()
        assert net.streams == [client]


async def test_a_stream_chunk_split_by_the_hook_keeps_its_order(anyio_backend: object) -> None:
    def fate(packet: Packet) -> Sequence[float]:
        return [0.003, 0.0, 0.001] if packet.kind == "stream" else [0.0]

    async with MemoryNetwork(fate=fate) as net:
        client, server = await connected(net)
        await client.send(b"abcdefgh")
        await client.send(b"ij")
        got = b""
        while len(got) < 10:
            got += await server.receive()
        assert got == b"abcdefghij"


async def test_a_reset_breaks_both_ends(anyio_backend: object) -> None:
    async with MemoryNetwork() as net:
        client, server = await connected(net)
        net.fate = lambda p: []  # the next chunk resets the connection
        await client.send(b"lost")
        for end in (client, server):
            with pytest.raises(anyio.BrokenResourceError):
                await end.receive()
        with pytest.raises(anyio.BrokenResourceError):
            await client.send(b"more")
        assert net.stats.resets == 1 and net.streams == []


async def test_a_sender_waits_for_room_in_the_window(anyio_backend: object) -> None:
    async with MemoryNetwork(stream_buffer=8) as net:
        client, server = await connected(net)
        await client.send(b"12345678")
        sent = anyio.Event()

        async def send_more() -> None:
            await client.send(b"9")
            sent.set()

        async with anyio.create_task_group() as tg:
            tg.start_soon(send_more)
            await anyio.wait_all_tasks_blocked()
            assert not sent.is_set()  # the window is full
            assert await server.receive() == b"12345678"
            await sent.wait()
            assert await server.receive() == b"9"


def test_a_lost_connection_request_leaves_the_caller_to_its_timeout() -> None:
    times: list[float] = []

    async def main() -> None:
        async with MemoryNetwork() as net:
            net.listen(*B)
            net.fate = lambda p: [] if p.kind == "connect" else [0.0]
            with anyio.move_on_after(5):
                await net.connect(*B)
            times.append(trio.current_time())
            net.fate = lambda p: [7.0] if p.kind == "connect" else [0.0]
            with anyio.move_on_after(5):  # given up before it arrives: it makes nothing
                await net.connect(*B)
            net.fate = lambda p: [0.25, 0.5]  # a duplicate request makes no second connection
            await net.connect(*B)
            times.append(trio.current_time())
            await trio.sleep(10)
            assert len(net.streams) == 2

    on_virtual_time(main)
    assert times == [5.0, 10.25]


def test_a_datagram_sent_from_an_asyncio_callback_arrives() -> None:
    """A session sends from event-loop callbacks under asyncio (a batch's flush, the Poller's
    timer). Under ``asyncio.run`` (not anyio's runner) no task and no anyio context is
    current there, and the send must need neither (it raised anyio's NoEventLoopError,
    found by tests/simulation)."""
    import asyncio

    async def main() -> None:
        async with MemoryNetwork() as net:
            a = net.datagram_socket(*A)
            b = net.datagram_socket(*B)
            loop = asyncio.get_running_loop()
            loop.call_soon(a.sendto, b"from a callback", B, context=contextvars.Context())
            with anyio.fail_after(10):  # (a guard: without the fix it never arrives)
                assert await b.receive() == (b"from a callback", A)
            assert net.stats.callback_errors == net.stats.hook_errors == 0

    asyncio.run(main())
