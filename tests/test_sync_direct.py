"""aiofins.sync's direct path: the calling thread drives the session on a blocking socket.

The peers are real: the virtual PLC served over loopback UDP and FINS/TCP by an event loop in
a thread of its own, or :class:`ScriptedPeer`, a UDP socket in a thread whose
:class:`~aiofins.simulator.VirtualPLC` answers each command unless its script says to drop
it or to answer "busy" (2604). Exact counts; no sleeps, no wall-clock bounds.
"""

from __future__ import annotations

import socket
import struct
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from anyio.from_thread import start_blocking_portal

import aiofins
import aiofins.sync
from aiofins._blocking import run_to_end
from aiofins.hooks import EventHooks
from aiofins.protocol.tcp import TcpDecoder, encode_frame, encode_node_response
from aiofins.session.states import LinkState
from aiofins.simulator import VirtualPLC, run_simulator
from tests.conftest import PTY_8N1, PTY_LINE


@pytest.fixture(scope="module")
def sim() -> Iterator[Any]:
    """A virtual PLC on loopback UDP and FINS/TCP, served by an event loop in a thread."""
    with (
        start_blocking_portal() as portal,
        portal.wrap_async_context_manager(
            run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0))
        ) as running,
    ):
        yield running


class ScriptedPeer:
    """A FINS/UDP peer on loopback in a thread of its own. The n-th datagram it receives is
    handled as ``script[n]`` says (``"answer"`` past its end): ``"answer"`` (the virtual
    PLC's reply), ``"drop"`` (none), ``"busy"`` (end code 2604, not executed), ``"refuse"``
    (end code 1103, address range exceeded)."""

    def __init__(self, script: list[str] | None = None) -> None:
        self.plc = VirtualPLC()
        self.script = list(script or [])
        #: Every datagram received, in order.
        self.received: list[bytes] = []
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port: int = self.sock.getsockname()[1]
        self.url = f"udp://127.0.0.1:{self.port}?node=1"
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            data, peer = self.sock.recvfrom(4096)
            if not data:  # close()'s empty datagram
                return
            self.received.append(data)
            action = self.script.pop(0) if self.script else "answer"
            if action == "drop":
                continue
            reply = self.plc.handle_frame(data)
            assert reply is not None
            if action == "busy":
                reply = reply[:12] + b"\x26\x04"
            elif action == "refuse":
                reply = reply[:12] + b"\x11\x03"
            self.sock.sendto(reply, peer)

    def close(self) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as poke:
            poke.sendto(b"", ("127.0.0.1", self.port))
        self.thread.join()
        self.sock.close()

    def __enter__(self) -> ScriptedPeer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def test_a_call_runs_in_the_calling_thread_and_no_thread_starts(sim: Any) -> None:
    threads: list[int] = []
    hooks = EventHooks(request_sent=[lambda _event: threads.append(threading.get_ident())])
    before = threading.active_count()
    with aiofins.sync.connect(f"udp://127.0.0.1:{sim.udp_port}", hooks=hooks) as plc:
        assert threading.active_count() == before
        plc.write("D100", [7, 8])
        assert plc.read("D100", 2) == [7, 8]
        assert threads == [threading.get_ident()] * 2
        assert plc.async_client.session.stats.completed == 2
        states = [plc.async_client.session.link_state]
    assert threading.active_count() == before
    states.append(plc.async_client.session.link_state)
    assert states == [LinkState.OPEN, LinkState.SHUT]


def test_fins_tcp_takes_its_node_from_the_handshake(sim: Any) -> None:
    with aiofins.sync.connect(f"tcp://127.0.0.1:{sim.tcp_port}") as plc:
        session = plc.async_client.session
        assert session.transport.local_node == session.source.node
        assert plc.dest.node == session.transport.remote_node
        plc.write("D200", [1, 2, 3])
        assert plc.read("D200", 3) == [1, 2, 3]
        assert len(plc.read_array("D0", 4000)) == 4000  # 5 frames (999 words each), pipelined
        assert session.stats.connects == 1 and session.stats.completed == 7


def test_a_read_over_many_frames_is_pipelined_and_reported_in_order(sim: Any) -> None:
    seen: list[tuple[int, int]] = []
    sim.plc.write("D3000", list(range(2000)))
    with aiofins.sync.connect(f"udp://127.0.0.1:{sim.udp_port}", max_in_flight=3) as plc:
        got = plc.read("D3000", 2000, progress=lambda done, total: seen.append((done, total)))
        assert got == list(range(2000))
        assert seen == [(999, 2000), (1998, 2000), (2000, 2000)]  # 999 words a frame
        assert plc.async_client.session.stats.completed == 3


def test_a_lost_datagram_is_sent_again_with_its_sid() -> None:
    with (
        ScriptedPeer(["drop"]) as peer,
        aiofins.sync.connect(peer.url, timeout=5.0) as plc,
    ):
        assert plc.read("D0") == [0]
        stats = plc.async_client.session.stats
        assert (stats.retries, stats.completed, stats.timeouts) == (1, 1, 0)
    assert len(peer.received) == 2 and peer.received[0] == peer.received[1]


def test_a_busy_plc_is_asked_again_after_a_pause() -> None:
    with ScriptedPeer(["busy", "busy"]) as peer, aiofins.sync.connect(peer.url) as plc:
        plc.write("D10", [5])
        assert plc.async_client.session.stats.busy_retries == 2
    assert len(peer.received) == 3
    assert peer.plc.read("D10") == [5]


def test_a_silent_plc_times_out_after_every_transmission_then_the_breaker_opens() -> None:
    script = ["drop"] * 3
    retried: list[int] = []
    hooks = EventHooks(request_retried=[lambda event: retried.append(event.attempt)])
    with (
        ScriptedPeer(script) as peer,
        aiofins.sync.connect(
            peer.url, timeout=0.3, retries=2, breaker_threshold=1, hooks=hooks
        ) as plc,
    ):
        with pytest.raises(aiofins.FinsTimeout, match="in 3 attempts"):
            plc.read("D0")
        with pytest.raises(aiofins.CircuitOpen):
            plc.read("D0")  # at once: nothing sent
        stats = plc.async_client.session.stats
        assert (stats.timeouts, stats.retries, stats.breaker_rejects) == (1, 2, 1)
        assert retried == [2, 3]
    assert len(peer.received) == 3 and len(set(peer.received)) == 1


def test_the_first_error_of_a_batch_is_raised_and_the_rest_given_up() -> None:
    # No retransmissions (retries=0): on a loaded machine a reply slower than the first
    # attempt's share of the timeout had its frame sent again, and the count was off.
    with (
        ScriptedPeer(["refuse"]) as peer,
        aiofins.sync.connect(peer.url, timeout=30, retries=0) as plc,
    ):
        with pytest.raises(aiofins.EndCodeError) as caught:
            plc.read("D0", 3000)  # 4 frames on the wire at once; the first one's reply: 1103
        assert caught.value.end_code.raw == 0x1103
        stats = plc.async_client.session.stats
        assert (stats.end_code_errors, stats.cancelled) == (1, 3)  # 3 given up, SIDs held
        assert plc.read("D0") == [0]  # the client goes on
    assert len(peer.received) == 5


def test_close_from_another_thread_ends_a_waiting_call() -> None:
    sent = threading.Event()
    hooks = EventHooks(request_sent=[lambda _event: sent.set()])
    with ScriptedPeer(["drop"]) as peer:
        plc = aiofins.sync.connect(peer.url, timeout=30, retries=0, hooks=hooks)
        raised: list[BaseException] = []

        def call() -> None:
            try:
                plc.read("D0")
            except BaseException as exc:
                raised.append(exc)

        caller = threading.Thread(target=call)
        caller.start()
        assert sent.wait(10)  # the request is registered: the call waits for its reply
        plc.close()
        caller.join(10)  # a bounded wait for the thread's end: the call's own timeout is 30 s
        assert not caller.is_alive()
        assert len(raised) == 1 and isinstance(raised[0], aiofins.ConnectionLost), raised
        assert plc.state is aiofins.sync.ClientState.CLOSED
        with pytest.raises(aiofins.ConnectionLost, match="closed"):
            plc.read("D0")
        assert plc.async_client.session.stats.cancelled == 1


def test_a_call_from_inside_a_call_is_refused(sim: Any) -> None:
    with aiofins.sync.connect(f"udp://127.0.0.1:{sim.udp_port}") as plc:

        def progress(done: int, total: int) -> None:
            plc.read("D0")

        with pytest.raises(RuntimeError, match="inside one of its calls"):
            plc.read("D0", 2000, progress=progress)
        assert plc.read("D1") == [sim.plc.read("D1")[0]]  # the client goes on


def test_threads_take_turns_on_one_client(sim: Any) -> None:
    sim.plc.write("D900", list(range(40)))
    with aiofins.sync.connect(f"udp://127.0.0.1:{sim.udp_port}") as plc:
        results: dict[int, list[int]] = {}

        def reader(i: int) -> None:
            results[i] = [plc.read(f"D{900 + i}")[0] for _ in range(10)]

        workers = [threading.Thread(target=reader, args=(i,)) for i in range(4)]
        for worker in workers:
            worker.start()
        for worker in workers:
            worker.join()
        assert results == {i: [i] * 10 for i in range(4)}
        assert plc.async_client.session.stats.completed == 40


def test_a_host_name_is_looked_up(sim: Any) -> None:
    with aiofins.sync.connect(f"udp://localhost:{sim.udp_port}?node=1") as plc:
        assert plc.read("D0", 1) == sim.plc.read("D0", 1)


def test_a_coroutine_that_waits_for_an_event_loop_is_refused() -> None:
    async def waits() -> None:
        import asyncio

        await asyncio.sleep(0)

    with pytest.raises(RuntimeError, match="waited for an event loop"):
        run_to_end(waits())


def test_backend_keeps_calls_on_the_loop_thread(sim: Any) -> None:
    def loops() -> int:
        return sum(thread.name == "aiofins.sync" for thread in threading.enumerate())

    with aiofins.sync.connect(f"udp://127.0.0.1:{sim.udp_port}", backend="asyncio") as plc:
        assert loops() == 1
        assert plc.read("D0", 1) == sim.plc.read("D0", 1)
    assert loops() == 0


class TwoConnections:
    """A FINS/TCP peer on loopback in a thread: its virtual PLC answers one command on the
    first connection, which it then ends (``reset``: with a reset, once the next command has
    come; else it closes it at once), and every command on the second."""

    def __init__(self, reset: bool) -> None:
        self.reset = reset
        self.plc = VirtualPLC()
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port: int = self.server.getsockname()[1]
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        for node, commands in ((9, 1), (10, None)):
            conn, _ = self.server.accept()
            with conn:
                decoder = TcpDecoder()
                conn.recv(100)  # the node address request
                conn.sendall(encode_node_response(node, 1))
                answered = 0
                while commands is None or answered < commands:
                    data = conn.recv(4096)
                    if not data:
                        break
                    for message in decoder.feed(data):
                        reply = self.plc.handle_frame(message.payload)
                        assert reply is not None
                        conn.sendall(encode_frame(reply))
                        answered += 1
                if self.reset and commands is not None:
                    conn.recv(4096)  # the next command: then a reset (no linger)
                    conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))

    def close(self) -> None:
        self.thread.join(10)
        self.server.close()


@pytest.mark.parametrize("reset", [False, True], ids=["closed", "reset"])
def test_fins_tcp_connects_again_after_the_plc_ended_the_connection(reset: bool) -> None:
    peer = TwoConnections(reset)
    states: list[str] = []
    hooks = EventHooks(connection_state_changed=[lambda event: states.append(event.new)])
    with aiofins.sync.connect(f"tcp://127.0.0.1:{peer.port}", hooks=hooks) as plc:
        assert plc.read("D0") == [0]
        assert plc.async_client.session.source.node == 9
        # The close is found by the next call (nothing reads between calls): it fails (the
        # end of the stream, or a reset if our frame reached the peer before its close) ...
        with pytest.raises(aiofins.ConnectionLost):
            plc.read("D0")
        # ... and the call after it connects again, by the link's rules.
        assert plc.read("D0") == [0]
        session = plc.async_client.session
        assert session.source.node == 10
        assert (session.stats.connects, session.stats.disconnects) == (2, 1)
    assert states == ["CONNECTING", "OPEN", "CLOSED", "CONNECTING", "OPEN", "SHUT"]
    peer.close()


def test_a_serial_line_runs_on_the_loop_thread(pty_pair: tuple[str, str]) -> None:
    plc_side, host_side = pty_pair
    url = f"serial://{host_side}?baudrate=115200&unit=0&{PTY_8N1}"
    with (
        start_blocking_portal() as portal,
        portal.wrap_async_context_manager(
            run_simulator(VirtualPLC(), serial=plc_side, serial_settings=PTY_LINE)
        ),
        aiofins.sync.connect(url, timeout=10.0) as plc,
    ):
        assert sum(thread.name == "aiofins.sync" for thread in threading.enumerate()) == 1
        plc.write("D50", [4, 5])
        assert plc.read("D50", 2) == [4, 5]
