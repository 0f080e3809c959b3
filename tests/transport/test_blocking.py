"""The blocking transports: UDP and FINS/TCP on a plain socket, against real peers.

A sink records what the transport hands it; the peers are loopback sockets of the test and
the virtual PLC's servers. No sleeps: a wait that passes is a ``receive`` that returns with
nothing, which is all that is asserted of it.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from anyio.from_thread import start_blocking_portal

from aiofins.protocol.errors import ConnectionLost, FinsTcpError, FrameError
from aiofins.protocol.tcp import (
    TcpCommand,
    encode_frame,
    encode_message,
    encode_node_response,
)
from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.transport.blocking import BlockingTcpTransport, BlockingUdpTransport

#: A MEMORY AREA READ of D0, one word (header from node 2 to node 1, SID 7).
READ_D0 = bytes([0x80, 0, 2, 0, 1, 0, 0, 2, 0, 7, 1, 1, 0x82, 0, 0, 0, 0, 1])


class Sink:
    """What a session would be told."""

    def __init__(self) -> None:
        self.frames: list[bytes] = []
        self.dropped: list[str] = []
        self.lost: list[BaseException | None] = []

    def frame_received(self, frame: bytes, _addr: object = None, /) -> None:
        self.frames.append(frame)

    def frame_dropped(self, reason: str) -> None:
        self.dropped.append(reason)

    def connection_lost(self, exc: BaseException | None) -> None:
        self.lost.append(exc)


@pytest.fixture(scope="module")
def sim() -> Iterator[Any]:
    with (
        start_blocking_portal() as portal,
        portal.wrap_async_context_manager(
            run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0))
        ) as running,
    ):
        yield running


@pytest.fixture
def peer() -> Iterator[socket.socket]:
    """A UDP socket on loopback playing the PLC by hand."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        yield sock


def test_udp_sends_a_frame_and_hands_the_reply_to_the_sink(sim: Any) -> None:
    transport = BlockingUdpTransport("127.0.0.1", sim.udp_port)
    sink = Sink()
    transport.connect(sink, 1.0)
    try:
        assert transport.is_open and transport.fast_send is not None
        transport.fast_send(READ_D0)
        while not sink.frames:
            transport.receive(5.0)
        reply = sink.frames[0]
        assert reply[0] == 0xC0 and reply[9] == 7 and reply[10:14] == b"\x01\x01\x00\x00"
    finally:
        transport.close()
    assert not transport.is_open and transport.fast_send is None


def test_udp_takes_datagrams_from_its_peer_only(peer: socket.socket) -> None:
    transport = BlockingUdpTransport("127.0.0.1", peer.getsockname()[1])
    sink = Sink()
    transport.connect(sink, 1.0)
    try:
        assert transport.fast_send is not None
        transport.fast_send(b"hello")
        data, ours = peer.recvfrom(100)
        assert data == b"hello"
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
            stranger.sendto(b"not yours", ours)  # dropped by the kernel: connected socket
        peer.sendto(b"yours", ours)
        while not sink.frames:
            transport.receive(5.0)
        assert sink.frames == [b"yours"]
    finally:
        transport.close()


def test_a_receive_whose_time_passes_hands_nothing(peer: socket.socket) -> None:
    transport = BlockingUdpTransport("127.0.0.1", peer.getsockname()[1])
    sink = Sink()
    transport.connect(sink, 1.0)
    try:
        transport.receive(0.001)
        transport.receive(0.0)  # no time left at all: the shortest wait, not "for ever"
        assert (sink.frames, sink.dropped, sink.lost) == ([], [], [])
    finally:
        transport.close()


def test_an_icmp_port_unreachable_is_counted_not_fatal(peer: socket.socket) -> None:
    port = peer.getsockname()[1]
    peer.close()  # nobody listens there now: the kernel answers port unreachable
    transport = BlockingUdpTransport("127.0.0.1", port)
    sink = Sink()
    transport.connect(sink, 1.0)
    try:
        assert transport.fast_send is not None
        transport.fast_send(READ_D0)
        while not sink.dropped:
            transport.receive(5.0)
        assert "refused" in sink.dropped[0].lower()
        assert transport.is_open and sink.lost == []
    finally:
        transport.close()


def test_interrupt_ends_a_receive_waiting_in_another_thread(peer: socket.socket) -> None:
    transport = BlockingUdpTransport("127.0.0.1", peer.getsockname()[1])
    transport.connect(Sink(), 1.0)
    raised: list[BaseException] = []

    def wait() -> None:
        try:
            transport.receive(30.0)
        except BaseException as exc:
            raised.append(exc)

    waiter = threading.Thread(target=wait)
    waiter.start()
    transport.interrupt()  # before or during its recv(): either way it ends now
    waiter.join(10)  # a bound on the test, not on the transport: the wait asked 30 s
    assert not waiter.is_alive()
    assert len(raised) == 1 and isinstance(raised[0], ConnectionLost)
    with pytest.raises(ConnectionLost, match="was closed"):
        transport.receive(1.0)
    transport.close()


def test_tcp_makes_the_handshake_and_carries_frames(sim: Any) -> None:
    transport = BlockingTcpTransport("127.0.0.1", sim.tcp_port)
    sink = Sink()
    transport.connect(sink, 5.0)
    try:
        assert transport.local_node is not None and transport.remote_node is not None
        assert transport.fast_send is not None
        frame = bytearray(READ_D0)
        frame[4], frame[7] = transport.remote_node, transport.local_node
        transport.fast_send(bytes(frame))
        transport.fast_send(bytes(frame))
        while len(sink.frames) < 2:
            transport.receive(5.0)
        assert [reply[10:14] for reply in sink.frames] == [b"\x01\x01\x00\x00"] * 2
    finally:
        transport.close()


class StreamPeer:
    """A FINS/TCP server on loopback for one connection: it answers the handshake with
    ``handshake`` (default: node 9 for us, its own 1); given ``after``, it waits for our
    first bytes and sends ``after``; then it closes."""

    def __init__(self, after: bytes = b"", handshake: bytes | None = None) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port: int = self.server.getsockname()[1]
        self.after = after
        self.handshake = encode_node_response(9, 1) if handshake is None else handshake
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        conn, _ = self.server.accept()
        with conn:
            conn.recv(100)  # the node address request
            conn.sendall(self.handshake)
            if self.after:
                conn.recv(100)
                conn.sendall(self.after)

    def close(self) -> None:
        self.thread.join(10)
        self.server.close()


def _receive_until_lost(transport: BlockingTcpTransport) -> BaseException:
    while True:
        try:
            transport.receive(5.0)
        except Exception as exc:
            return exc


def test_tcp_a_peer_that_closes_ends_the_link_with_connection_lost() -> None:
    peer = StreamPeer()
    transport = BlockingTcpTransport("127.0.0.1", peer.port)
    sink = Sink()
    transport.connect(sink, 5.0)
    assert (transport.local_node, transport.remote_node) == (9, 1)
    error = _receive_until_lost(transport)
    assert isinstance(error, ConnectionLost) and "closed the connection" in str(error)
    assert sink.lost == [error] and not transport.is_open
    peer.close()


def test_tcp_a_frame_then_an_error_notification_ends_the_link() -> None:
    reply = bytes([0xC0, 0, 2, 0, 9, 0, 0, 1, 0, 7, 1, 1, 0, 0, 0, 0])
    notification = encode_message(TcpCommand.FRAME_ERROR, b"", 0x01)
    peer = StreamPeer(encode_frame(reply) + notification)
    transport = BlockingTcpTransport("127.0.0.1", peer.port)
    sink = Sink()
    transport.connect(sink, 5.0)
    assert transport.fast_send is not None
    transport.fast_send(READ_D0)
    error = _receive_until_lost(transport)
    assert sink.frames == [reply]
    assert isinstance(error, FinsTcpError) and error.tcp_error_code == 0x01
    assert sink.lost == [error] and not transport.is_open
    peer.close()


def test_tcp_a_handshake_that_breaks_the_protocol_fails_the_connect() -> None:
    peer = StreamPeer(handshake=encode_node_response(0, 1))  # node 0: none assigned
    transport = BlockingTcpTransport("127.0.0.1", peer.port)
    with pytest.raises(FrameError):
        transport.connect(Sink(), 5.0)
    assert not transport.is_open
    peer.close()


def test_tcp_a_refused_connection_is_connection_lost(peer: socket.socket) -> None:
    with socket.socket() as probe:  # a port with no listener
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(ConnectionLost, match="cannot connect"):
        BlockingTcpTransport("127.0.0.1", port).connect(Sink(), 5.0)
