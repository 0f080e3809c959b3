"""The simulator's UDP, TCP and serial servers, driven with hand-built bytes over loopback."""

from __future__ import annotations

import math
import os
import random
import re
import shutil
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator
from typing import Any

import anyio
import pytest
from anyio.abc import SocketStream
from anyio.streams.buffered import BufferedByteReceiveStream

from aiofins.simulator import FaultPlan, FaultRule, Simulator, VirtualPLC, run_simulator
from aiofins.simulator import tcp as tcp_server
from tests.conftest import PTY_LINE

from ..virtual_time import on_virtual_time

pytestmark = pytest.mark.anyio

# wire-format §8.1: read D100 x 10 from node 0x0A as node 0x22, SID 01.
READ_D100 = bytes.fromhex("80 00 02 00 0A 00 00 22 00 01 01 01 82 00 64 00 00 0A")
READ_D100_REPLY = bytes.fromhex(
    "C0 00 02 00 22 00 00 0A 00 01 01 01 00 00"
    "00 01 00 02 00 03 00 04 00 05 00 06 00 07 00 08 00 09 00 0A"
)


def make_plc() -> VirtualPLC:
    """Node 10 with D100..D109 = 1..10 (the worked examples' data)."""
    plc = VirtualPLC(node=10)
    plc.memory.write_words(0x82, 100, list(range(1, 11)))
    return plc


@pytest.fixture
async def sim() -> AsyncIterator[Simulator]:
    async with run_simulator(
        make_plc(), udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0), faults=FaultPlan(seed=1)
    ) as running:
        yield running


def with_sid(frame: bytes, sid: int) -> bytes:
    return frame[:9] + bytes((sid,)) + frame[10:]


# ---- UDP ------------------------------------------------------------------------------------


async def udp_exchange(port: int, frame: bytes) -> bytes:
    async with await anyio.create_udp_socket(local_host="127.0.0.1") as sock:
        await sock.sendto(frame, "127.0.0.1", port)
        with anyio.fail_after(5):
            data, _ = await sock.receive()
        return data


async def test_udp_answers_worked_example(sim: Simulator) -> None:
    assert await udp_exchange(sim.udp_port, READ_D100) == READ_D100_REPLY


async def test_udp_replies_to_each_sender_with_its_sid(sim: Simulator) -> None:
    async with (
        await anyio.create_udp_socket(local_host="127.0.0.1") as a,
        await anyio.create_udp_socket(local_host="127.0.0.1") as b,
    ):
        await a.sendto(with_sid(READ_D100, 0x11), "127.0.0.1", sim.udp_port)
        await b.sendto(with_sid(READ_D100, 0x22), "127.0.0.1", sim.udp_port)
        with anyio.fail_after(5):
            reply_a, addr_a = await a.receive()
            reply_b, addr_b = await b.receive()
    assert addr_a == ("127.0.0.1", sim.udp_port) == addr_b
    assert reply_a == with_sid(READ_D100_REPLY, 0x11)
    assert reply_b == with_sid(READ_D100_REPLY, 0x22)
    assert sim.counters.requests == 2
    assert sim.counters.responses == 2


async def test_udp_no_response_wanted_sends_nothing_then_serves_next(sim: Simulator) -> None:
    silent = bytes((0x81,)) + READ_D100[1:]
    async with await anyio.create_udp_socket(local_host="127.0.0.1") as sock:
        await sock.sendto(silent, "127.0.0.1", sim.udp_port)
        await sock.sendto(with_sid(READ_D100, 7), "127.0.0.1", sim.udp_port)
        with anyio.fail_after(5):
            data, _ = await sock.receive()
    assert data == with_sid(READ_D100_REPLY, 7)


# ---- TCP ------------------------------------------------------------------------------------

NODE_REQUEST_AUTO = bytes.fromhex("46494E53 0000000C 00000000 00000000 00000000")


def node_request(node: int) -> bytes:
    return bytes.fromhex("46494E53 0000000C 00000000 00000000") + node.to_bytes(4, "big")


def node_response(client: int, server: int, error: int = 0) -> bytes:
    return (
        bytes.fromhex("46494E53 00000010 00000001")
        + error.to_bytes(4, "big")
        + client.to_bytes(4, "big")
        + server.to_bytes(4, "big")
    )


def tcp_frame(frame: bytes) -> bytes:
    return (
        b"FINS"
        + (8 + len(frame)).to_bytes(4, "big")
        + bytes(4 * 0)
        + (bytes.fromhex("00000002 00000000") + frame)
    )


class Peer:
    """A raw FINS/TCP client socket."""

    def __init__(self, stream: SocketStream) -> None:
        self.stream = stream
        self.reader = BufferedByteReceiveStream(stream)

    async def read(self, n: int) -> bytes:
        with anyio.fail_after(5):
            return await self.reader.receive_exactly(n)

    async def read_message(self) -> bytes:
        head = await self.read(8)
        return head + await self.read(int.from_bytes(head[4:8], "big"))

    async def closed_by_server(self) -> bool:
        with anyio.fail_after(5):
            try:
                await self.reader.receive()
            except (anyio.EndOfStream, anyio.BrokenResourceError):
                return True
        return False


async def connect(port: int) -> Peer:
    return Peer(await anyio.connect_tcp("127.0.0.1", port))


async def handshake(port: int, node: int = 0) -> tuple[Peer, bytes]:
    peer = await connect(port)
    await peer.stream.send(node_request(node))
    return peer, await peer.read_message()


async def test_tcp_worked_example(sim: Simulator) -> None:
    peer = await connect(sim.tcp_port)
    async with peer.stream:
        await peer.stream.send(NODE_REQUEST_AUTO)
        # wire-format §8.2: client node EF allocated, server node 0A
        assert await peer.read(24) == bytes.fromhex(
            "46 49 4E 53 00 00 00 10 00 00 00 01 00 00 00 00 00 00 00 EF 00 00 00 0A"
        )
        request = bytes.fromhex(
            "46 49 4E 53 00 00 00 1A 00 00 00 02 00 00 00 00 "
            "80 00 02 00 0A 00 00 EF 00 02 01 01 82 00 64 00 00 0A"
        )
        await peer.stream.send(request)
        assert await peer.read(50) == bytes.fromhex(
            "46 49 4E 53 00 00 00 2A 00 00 00 02 00 00 00 00 C0 00 02 00 EF 00 00 0A 00 02 "
            "01 01 00 00 00 01 00 02 00 03 00 04 00 05 00 06 00 07 00 08 00 09 00 0A"
        )


async def test_tcp_allocates_distinct_nodes(sim: Simulator) -> None:
    a, reply_a = await handshake(sim.tcp_port)
    b, reply_b = await handshake(sim.tcp_port)
    async with a.stream, b.stream:
        assert reply_a == node_response(0xEF, 10)
        assert reply_b == node_response(0xF0, 10)
        assert sim.tcp is not None
        assert sim.tcp.connected_nodes == [0xEF, 0xF0]


async def test_tcp_fixed_node_and_duplicate(sim: Simulator) -> None:
    a, reply_a = await handshake(sim.tcp_port, 5)
    async with a.stream:
        assert reply_a == node_response(5, 10)
        b, reply_b = await handshake(sim.tcp_port, 5)
        async with b.stream:
            assert reply_b == node_response(5, 10, 0x21)
            assert await b.closed_by_server()
        # W421: the holder of node 5 gets a connection confirmation (command 6)
        assert await a.read_message() == bytes.fromhex("46494E53 00000008 00000006 00000000")


@pytest.mark.parametrize(("node", "error"), [(10, 0x24), (255, 0x23), (0x1000, 0x23)])
async def test_tcp_refuses_bad_fixed_node(sim: Simulator, node: int, error: int) -> None:
    peer, reply = await handshake(sim.tcp_port, node)
    async with peer.stream:
        assert reply == node_response(node, 10, error)
        assert await peer.closed_by_server()


async def test_tcp_no_free_node_and_reuse_after_close() -> None:
    async with run_simulator(make_plc(), tcp=("127.0.0.1", 0), node_pool=(239,)) as sim:
        a, reply_a = await handshake(sim.tcp_port)
        assert reply_a == node_response(239, 10)
        b, reply_b = await handshake(sim.tcp_port)
        async with b.stream:
            assert reply_b == node_response(0, 10, 0x25)
            assert await b.closed_by_server()
        await a.stream.aclose()
        assert sim.tcp is not None
        with anyio.fail_after(5):
            while sim.tcp.connected_nodes:  # wait for the server to see the close
                await anyio.sleep(0.001)
        c, reply_c = await handshake(sim.tcp_port)
        async with c.stream:
            assert reply_c == node_response(239, 10)


async def test_tcp_max_connections() -> None:
    async with run_simulator(make_plc(), tcp=("127.0.0.1", 0), max_connections=1) as sim:
        a, reply_a = await handshake(sim.tcp_port)
        async with a.stream:
            assert reply_a == node_response(239, 10)
            b, reply_b = await handshake(sim.tcp_port)
            async with b.stream:
                assert reply_b == node_response(0, 10, 0x20)
                assert await b.closed_by_server()
        assert sim.tcp is not None and sim.tcp.handshake_refusals == 1


async def test_idle_sockets_do_not_lock_clients_out() -> None:
    """17 sockets that never sent a handshake locked every FINS/TCP client out (the limit
    counted them, decided at accept). Now only handshaken connections count, and sockets
    without a handshake are capped at 8: the oldest are closed to make room."""
    async with run_simulator(make_plc(), tcp=("127.0.0.1", 0)) as sim:
        assert sim.tcp is not None and sim.tcp.max_connections == 16
        idle = [await connect(sim.tcp_port) for _ in range(17)]
        try:
            ok, reply = await handshake(sim.tcp_port)
            async with ok.stream:
                assert reply == node_response(239, 10)
                await ok.stream.send(tcp_frame(READ_D100))
                reply_to_239 = READ_D100_REPLY[:4] + bytes((239,)) + READ_D100_REPLY[5:]
                assert (await ok.read_message())[16:] == reply_to_239  # DA1: its node
            # accepted 18 sockets with room for 8 waiting: the 10 oldest idle ones closed
            assert sim.tcp.pending_evictions == 10
            for peer in idle[:10]:
                assert await peer.closed_by_server()
        finally:
            for peer in idle:
                await peer.stream.aclose()


async def test_the_connection_limit_counts_handshaken_connections_only() -> None:
    async with run_simulator(make_plc(), tcp=("127.0.0.1", 0), max_connections=2) as sim:
        idle = [await connect(sim.tcp_port) for _ in range(3)]
        a, reply_a = await handshake(sim.tcp_port)
        b, reply_b = await handshake(sim.tcp_port)
        c, reply_c = await handshake(sim.tcp_port)
        async with a.stream, b.stream, c.stream:
            assert (reply_a, reply_b) == (node_response(239, 10), node_response(240, 10))
            assert reply_c == node_response(0, 10, 0x20)  # two handshaken: all in use
            assert await c.closed_by_server()
        assert sim.tcp is not None and sim.tcp.pending_evictions == 0
        for peer in idle:
            await peer.stream.aclose()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_connections": math.nan}, "max_connections must be a whole number, at least 1"),
        ({"max_pending": math.nan}, "max_pending must be a whole number, at least 1"),
        ({"max_pending": 1.5}, "max_pending must be a whole number"),
        ({"server_node": 1.5}, "server node must be a whole number, 1..254"),
        ({"node_pool": (239, 300)}, r"node pool: node 300 out of range 1\.\.254"),
        ({"node_pool": (0,)}, r"node pool: node 0 out of range 1\.\.254"),
    ],
)
async def test_tcp_server_refuses_limits_that_limit_nothing(
    kwargs: dict[str, Any], message: str
) -> None:
    """``max_pending=nan`` passed the ``< 1`` check and every ``>= nan`` was false: idle
    sockets were unbounded again; a node pool with 300 had the simulator assign node 300."""
    with pytest.raises(ValueError, match=message):
        async with run_simulator(make_plc(), tcp=("127.0.0.1", 0), **kwargs):
            pass


@on_virtual_time
async def test_tcp_connection_without_handshake_is_closed() -> None:
    """A connection that never sends the handshake held a descriptor forever (enough of
    them and accept() failed). On virtual time (asyncio, trio; uvloop's clock cannot be
    virtual): a loaded machine's slow handshake is not taken for a missing one, and the
    time the silent one is given is exact."""
    assert tcp_server.HANDSHAKE_TIMEOUT <= 2  # short: a real client shakes hands at once
    async with run_simulator(make_plc(), tcp=("127.0.0.1", 0), handshake_timeout=0.1) as sim:
        peer = await connect(sim.tcp_port)
        start = anyio.current_time()
        async with peer.stream:
            assert await peer.closed_by_server()
        assert anyio.current_time() - start == pytest.approx(0.1, abs=1e-6)
        assert sim.tcp is not None and sim.tcp.handshake_timeouts == 1
        ok, reply = await handshake(sim.tcp_port)  # a client that does shake hands stays
        async with ok.stream:
            assert reply == node_response(239, 10)
            await anyio.sleep(0.3)  # three handshake timeouts pass
            await ok.stream.send(tcp_frame(READ_D100))
            assert (await ok.read_message())[16:18] == b"\xc0\x00"  # the FINS reply
        assert sim.tcp.handshake_timeouts == 1


async def test_tcp_accept_failure_does_not_stop_the_simulator(tmp_path: object) -> None:
    """Out of file descriptors (EMFILE), accept() failed and the whole simulator (UDP
    included) exited. In a process with a low descriptor limit: fill it, then it must
    still answer over UDP and, once descriptors are free, over TCP. (The simulator uses
    about 10 descriptors of its own; sockets without a handshake are capped at 8, so the
    limit must be lower than that for accept() to fail.)"""
    script = (
        "import resource, sys; resource.setrlimit(resource.RLIMIT_NOFILE, (17, 17)); "
        "from aiofins.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            script,
            "simulate",
            "--udp",
            "127.0.0.1:0",
            "--tcp",
            "127.0.0.1:0",
            "--node",
            "10",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        urls = {}
        for line in proc.stdout:
            if line.startswith("listening on "):
                url = line.split()[-1]
                urls[url[:3]] = int(url.rsplit(":", 1)[1])
            if len(urls) == 2:
                break
        streams = []
        for _ in range(60):  # more than the process has descriptors for
            streams.append(await anyio.connect_tcp("127.0.0.1", urls["tcp"]))
        await anyio.sleep(0.3)  # the simulator's accepts fail meanwhile
        for stream in streams:
            await stream.aclose()
        assert proc.poll() is None  # still running
        async with await anyio.create_connected_udp_socket("127.0.0.1", urls["udp"]) as udp:
            await udp.send(READ_D100)
            with anyio.fail_after(5):
                assert (await udp.receive())[:2] == b"\xc0\x00"
        with anyio.fail_after(10):
            while True:  # TCP comes back as the closed connections free descriptors
                try:
                    ok, reply = await handshake(urls["tcp"])
                    break
                except (OSError, anyio.EndOfStream, anyio.BrokenResourceError):
                    await anyio.sleep(0.1)
        async with ok.stream:
            assert reply == node_response(239, 10)
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=10)
    assert "Traceback" not in err and "tcp_accept_errors=" in err, err


async def test_tcp_split_and_merged_frames(sim: Simulator) -> None:
    peer, reply = await handshake(sim.tcp_port)
    async with peer.stream:
        assert reply == node_response(0xEF, 10)
        message = tcp_frame(with_sid(READ_D100, 1))
        for i in range(len(message)):  # one byte per write
            await peer.stream.send(message[i : i + 1])
        expected = with_sid(READ_D100_REPLY, 1)
        expected = expected[:4] + b"\xef" + expected[5:]
        assert await peer.read_message() == tcp_frame(expected)
        await peer.stream.send(tcp_frame(with_sid(READ_D100, 2)) + tcp_frame(READ_D100[:12]))
        second = with_sid(expected, 2)
        assert await peer.read_message() == tcp_frame(second)
        third = await peer.read_message()
        assert third[16:28] == with_sid(expected, 1)[:12]


async def test_tcp_fills_source_node(sim: Simulator) -> None:
    peer, _ = await handshake(sim.tcp_port)
    async with peer.stream:
        await peer.stream.send(tcp_frame(READ_D100))  # SA1 = 0x22, allocated node is EF
        reply = await peer.read_message()
        assert reply[16 + 4] == 0xEF  # DA1 of the response
        assert sim.tcp is not None
        assert sim.tcp.source_node_rewrites == 1


@pytest.mark.parametrize(
    ("data", "error"),
    [
        (b"FINX" + bytes(12), 1),
        (b"FINS" + (0x10000).to_bytes(4, "big") + bytes(8), 2),
    ],
)
async def test_tcp_bad_envelope_gets_error_notification(
    sim: Simulator, data: bytes, error: int
) -> None:
    peer = await connect(sim.tcp_port)
    async with peer.stream:
        await peer.stream.send(data)
        assert await peer.read_message() == bytes.fromhex(
            "46494E53 00000008 00000003"
        ) + error.to_bytes(4, "big")
        assert await peer.closed_by_server()
    assert sim.tcp is not None and sim.tcp.error_notifications == 1


async def test_tcp_second_handshake_gets_command_3(sim: Simulator) -> None:
    peer, _ = await handshake(sim.tcp_port)
    async with peer.stream:
        await peer.stream.send(NODE_REQUEST_AUTO)
        assert await peer.read_message() == bytes.fromhex("46494E53 00000008 00000003 00000003")
        assert await peer.closed_by_server()


async def test_tcp_frame_before_handshake_gets_command_3(sim: Simulator) -> None:
    peer = await connect(sim.tcp_port)
    async with peer.stream:
        await peer.stream.send(tcp_frame(READ_D100))
        assert await peer.read_message() == bytes.fromhex("46494E53 00000008 00000003 00000003")
        assert await peer.closed_by_server()


# ---- serial (Host Link over a socat pty pair) -----------------------------------------------


@pytest.fixture
def pty_pair() -> Iterator[tuple[str, str]]:
    if shutil.which("socat") is None:
        pytest.skip("socat is not installed")
    proc = subprocess.Popen(
        ["socat", "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"],
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    devices: list[str] = []
    try:
        while len(devices) < 2:
            line = proc.stderr.readline()
            if not line:
                pytest.fail("socat exited before announcing its ptys")
            match = re.search(r"PTY is (\S+)", line)
            if match:
                devices.append(match.group(1))
        yield devices[0], devices[1]
    finally:
        proc.terminate()
        proc.wait(5)
        proc.stderr.close()


class Line:
    """The host end of the serial line (the other pty)."""

    def __init__(self, device: str) -> None:
        self.fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.buffer = b""

    async def write(self, data: bytes) -> None:
        os.write(self.fd, data)

    async def read_line(self) -> bytes:
        with anyio.fail_after(5):
            while b"\r" not in self.buffer:
                await anyio.wait_readable(self.fd)
                try:
                    self.buffer += os.read(self.fd, 4096)
                except BlockingIOError:
                    continue
        line, _, self.buffer = self.buffer.partition(b"\r")
        return line + b"\r"

    def close(self) -> None:
        os.close(self.fd)


# wire-format §8.3
HOSTLINK_READ = b"@00FA000000000010182006400000A0E*\r"
HOSTLINK_REPLY = b"@00FA004000000001010000000100020003000400050006000700080009000A33*\r"


@pytest.mark.serial
async def test_serial_worked_example(pty_pair: tuple[str, str]) -> None:
    server_end, host_end = pty_pair
    async with run_simulator(make_plc(), serial=server_end, serial_settings=PTY_LINE) as sim:
        line = Line(host_end)
        try:
            await line.write(HOSTLINK_READ)
            assert await line.read_line() == HOSTLINK_REPLY
            # noise, a bad FCS and another unit number are ignored; the next line is served
            bad_fcs = HOSTLINK_READ.replace(b"0E*", b"0F*")
            other_unit = b"@01FA000000000010182006400000A0F*\r"
            await line.write(b"xx" + bad_fcs + other_unit + HOSTLINK_READ)
            assert await line.read_line() == HOSTLINK_REPLY
            assert sim.serial is not None
            assert sim.serial.ignored_lines == 2
        finally:
            line.close()


@pytest.mark.serial
async def test_a_stray_at_sign_does_not_swallow_the_next_command(
    pty_pair: tuple[str, str],
) -> None:
    server_end, host_end = pty_pair
    async with run_simulator(make_plc(), serial=server_end, serial_settings=PTY_LINE) as sim:
        line = Line(host_end)
        try:
            await line.write(b"@" + HOSTLINK_READ)
            assert await line.read_line() == HOSTLINK_REPLY
            await line.write(HOSTLINK_READ[:10] + HOSTLINK_READ)  # a command cut off
            assert await line.read_line() == HOSTLINK_REPLY
            assert sim.serial is not None and sim.serial.ignored_lines == 0
        finally:
            line.close()


@pytest.mark.serial
async def test_serial_unit_number_filter(pty_pair: tuple[str, str]) -> None:
    server_end, host_end = pty_pair
    async with run_simulator(
        make_plc(), serial=server_end, serial_settings=PTY_LINE, serial_unit=1
    ) as sim:
        line = Line(host_end)
        try:
            await line.write(HOSTLINK_READ + b"@01FA000000000010182006400000A0F*\r")
            reply = await line.read_line()
            assert reply.startswith(b"@01FA0040000000010100000001")
            assert sim.serial is not None
            assert sim.serial.ignored_lines == 1
        finally:
            line.close()


# ---- robustness: garbage never stops a server -----------------------------------------------


def garbage(seed: int, count: int) -> list[bytes]:
    rng = random.Random(seed)
    out = []
    for _ in range(count):
        frame = bytearray(rng.randbytes(rng.randrange(0, 40)))
        if frame and rng.random() < 0.5:
            frame[0] = 0x80  # looks like a command often enough to reach the PLC
        if len(frame) > 4 and rng.random() < 0.5:
            frame[4] = 0x0A
        out.append(bytes(frame))
    return out


async def test_udp_survives_garbage(sim: Simulator) -> None:
    async with await anyio.create_udp_socket(local_host="127.0.0.1") as sock:
        for frame in garbage(1, 300):
            await sock.sendto(frame, "127.0.0.1", sim.udp_port)
        await sock.sendto(with_sid(READ_D100, 0x5A), "127.0.0.1", sim.udp_port)
        with anyio.fail_after(5):
            while (data := (await sock.receive())[0])[9:10] != b"\x5a":
                assert data[0] & 0x40  # whatever came back is a response
    assert data == with_sid(READ_D100_REPLY, 0x5A)
    assert sim.counters.handler_errors == 0


async def test_tcp_survives_garbage_frames(sim: Simulator) -> None:
    peer, _ = await handshake(sim.tcp_port)
    async with peer.stream:
        for frame in garbage(2, 300):
            await peer.stream.send(tcp_frame(frame))
        await peer.stream.send(tcp_frame(with_sid(READ_D100, 0x5A)))
        while (message := await peer.read_message())[16 + 9] != 0x5A:
            assert message[8:16] == bytes.fromhex("00000002 00000000")
    assert message[16 + 12 : 16 + 14] == b"\x00\x00"
    assert sim.counters.handler_errors == 0


def hostlink(body: bytes) -> bytes:
    """Append the FCS (XOR of every character) and the terminator, by hand."""
    fcs = 0
    for c in body:
        fcs ^= c
    return body + b"%02X*\r" % fcs


@pytest.mark.serial
async def test_serial_full_header_long_response_and_fault(pty_pair: tuple[str, str]) -> None:
    server_end, host_end = pty_pair
    plan = FaultPlan(per_command={0x0601: FaultRule(corrupt=1.0)}, seed=4)
    async with run_simulator(make_plc(), serial=server_end, serial_settings=PTY_LINE, faults=plan):
        line = Line(host_end)
        try:
            # full header to network 0, node 0 (the CPU at the port), SID 07, read D100 x 2
            await line.write(
                hostlink(b"@00FA0" + b"80000200000000000007" + b"010182006400" + b"0002")
            )
            assert await line.read_line() == hostlink(
                b"@00FA00" + b"C00002000000000A0007" + b"0101" + b"0000" + b"00010002"
            )
            # 270 words (540 bytes) exceed the 538 data bytes of a Host Link response: 110B
            await line.write(hostlink(b"@00FA0" + b"00000000" + b"010182006400" + b"%04X" % 270))
            assert await line.read_line() == hostlink(b"@00FA0040000000" + b"0101110B")
            # a corrupted response: still '@' ... '*' CR, but the FCS no longer matches
            await line.write(hostlink(b"@00FA0" + b"00000000" + b"0601"))
            reply = await line.read_line()
            assert reply.startswith(b"@") and reply.endswith(b"*\r")
            assert hostlink(reply[:-4]) != reply
        finally:
            line.close()
