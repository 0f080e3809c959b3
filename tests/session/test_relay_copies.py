"""Copies of relay errors (issue #22, the simulation's relay family): a relay error comes
from the relay point, under the relay's own address, and is matched by SID and command code
alone; a copy the network made of one must never reach a later request that took its SID.

The client is the real :class:`~aiofins.transport.UdpTransport` on :mod:`aiofins.memnet`;
the PLCs are the simulator's :class:`~aiofins.simulator.plant.Plant` (its gateway answers
0205, "no response", with bit 15 for a node missing on its Controller Link network); the
network's fault hook copies and delays replies. On virtual time: every time is exact."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager

import anyio
import pytest

from aiofins.memnet import MemoryNetwork, Packet
from aiofins.protocol.errors import FinsTimeout, RelayError
from aiofins.protocol.header import FinsAddress
from aiofins.protocol.limits import NetworkType
from aiofins.session import Session
from aiofins.simulator.plant import Network, Plant, RoutingTables, Station, StationState, Unit
from aiofins.simulator.plc import VirtualPLC
from aiofins.transport import UdpTransport

from ..virtual_time import on_virtual_time

#: The gateway: its CPU at 1.10.0, its Ethernet unit at 10.0.0.10, a Controller Link unit on
#: network 2 (node 1); the cell PLC at 2.2.0 on that network; nobody at 2.9.0. The client:
#: 1.200.0 at 10.0.0.200.
GATEWAY = FinsAddress(1, 10, 0)
CELL = FinsAddress(2, 2, 0)
MISSING = FinsAddress(2, 9, 0)
CLIENT = FinsAddress(1, 200, 0)
RELAY_ERROR = 0x8205


def words(first: int, count: int) -> list[int]:
    return list(range(first, first + count))


def gateway() -> tuple[Plant, Unit]:
    """The plant: the gateway (D0.. hold 100, 101, ...) and the cell (D0.. hold 2000, ...)."""
    line = VirtualPLC(network=1, node=10)
    line.write("D0", words(100, 300))
    cell = VirtualPLC(network=2, node=2)
    cell.write("D0", words(2000, 300))
    ethernet = Unit(0x10, 1, 10, host="10.0.0.10")
    plant = Plant(
        [Network(1, NetworkType.ETHERNET), Network(2, NetworkType.CONTROLLER_LINK)],
        [
            Station(
                "line",
                line,
                [ethernet, Unit(0x11, 2, 1)],
                RoutingTables(local={0x10: 1, 0x11: 2}),
            ),
            Station("cell", cell, [Unit(0x10, 2, 2)], RoutingTables({0x10: 2}, relay={1: (2, 1)})),
        ],
    )
    return plant, ethernet


@asynccontextmanager
async def plant_session(
    fate: Callable[[Packet], Sequence[float]], **options: object
) -> AsyncIterator[tuple[Session, Plant, list[bytes]]]:
    """A session to the gateway's CPU over memnet with the fault hook ``fate``; yields it,
    the plant and the commands the gateway received."""
    plant, unit = gateway()
    received: list[bytes] = []
    async with MemoryNetwork(fate=fate) as net:
        sock = net.datagram_socket("10.0.0.10", 9600)

        async def serve() -> None:
            while True:
                data, (host, port) = await sock.receive()
                received.append(data)
                for out in plant.receive(unit, data, host, port):
                    sock.sendto(out.frame, (out.host, out.port))

        async with anyio.create_task_group() as tg:
            tg.start_soon(serve)
            transport = UdpTransport("10.0.0.10", local_host="10.0.0.200", network=net)
            async with Session(
                transport,
                source=CLIENT,
                dest=GATEWAY,
                max_sid_spaces=1,
                **options,  # type: ignore[arg-type]
            ) as session:
                yield session, plant, received
            tg.cancel_scope.cancel()


def read(word: int, count: int = 1) -> bytes:
    """0101 parameters: DM words."""
    return bytes((0x82, word >> 8, word & 0xFF, 0, count >> 8, count & 0xFF))


def copying_relay_errors(
    late: float, slow: Callable[[bytes], bool]
) -> Callable[[Packet], Sequence[float]]:
    """A fault hook: every relay error reaches the client twice, the copy ``late`` s after
    the first; a reply ``slow`` picks comes 0.1 s late; the rest at once."""

    def fate(packet: Packet) -> Sequence[float]:
        data = packet.data
        if packet.source[0] != "10.0.0.10" or len(data) < 14:
            return [0.0]
        if data[12] & 0x80:
            return [0.0, late]
        return [0.1] if slow(data) else [0.0]

    return fate


@on_virtual_time
async def test_a_copy_of_a_relay_error_never_reaches_the_relay_s_own_cpu() -> None:
    """A read to 2.9.0 gets the gateway's relay error (0205 from 1.10, bit 15): its key is
    the gateway CPU's own, 1.10.0 and the read's SID, 0. The network copies it 0.05 s
    later. The next read, of the gateway's CPU, whose reply takes 0.1 s, took SID 0 (each
    destination's SIDs come round in turn from 0; SID 0 was answered): the copy answered
    it, exactly by key, and it raised 2.9.0's RelayError (the soak's seeds 40044 and
    40059). The SID a relay error answered now lingers 0.5 s, for every destination: the
    read takes SID 1 and gets its own words; the copy is counted as a duplicate, 0.05 s
    late (the link learns a 0.1 s linger)."""
    fate = copying_relay_errors(0.05, lambda reply: True)
    async with plant_session(fate, timeout=1.0, retries=0) as (session, plant, received):
        with pytest.raises(RelayError) as info:
            await session.request(0x01, 0x01, read(0), dest=MISSING)
        error = info.value
        assert (error.end_code.raw, error.network, error.node) == (RELAY_ERROR, 1, 10)
        assert anyio.current_time() == 0.0  # the copy is on its way
        r = await session.request(0x01, 0x01, read(7, 2))
        assert r.data == bytes.fromhex("006b006c")  # 107, 108
        assert anyio.current_time() == pytest.approx(0.1, abs=1e-6)
        assert [(f[3:6], f[9]) for f in received] == [(b"\x02\x09\x00", 0), (b"\x01\x0a\x00", 1)]
        assert plant.counts["refused:0205"] == 1
        stats = session.stats
        assert (stats.completed, stats.end_code_errors) == (1, 1)
        assert (stats.duplicates, stats.unsolicited, stats.late_replies) == (1, 0, 0)
        assert session.sids.linger == pytest.approx(0.1)


@on_virtual_time
async def test_a_copy_of_a_relay_error_never_answers_the_sid_s_next_request() -> None:
    """One destination, the cell at 2.2.0, down at first: the gateway answers the first
    read (SID 0) with 0205 and bit 15, and the network copies that 0.05 s later. The cell
    is up again; 255 reads take SIDs 1 to 255 at once, and the 257th read, whose reply
    takes 0.1 s, comes back round to SID 0: the copy, matched by SID and command code,
    raised the relay error to it though the cell answered. Now it takes SID 1 and gets the
    cell's words."""
    fate = copying_relay_errors(0.05, lambda reply: reply[14:16] == (2256).to_bytes(2, "big"))
    async with plant_session(fate, timeout=1.0, retries=0) as (session, plant, received):
        plant.station("cell").state = StationState.DOWN
        with pytest.raises(RelayError):
            await session.request(0x01, 0x01, read(0), dest=CELL)
        plant.station("cell").state = StationState.UP
        for word in range(1, 256):
            r = await session.request(0x01, 0x01, read(word), dest=CELL)
            assert r.data == (2000 + word).to_bytes(2, "big")
        assert anyio.current_time() == 0.0
        r = await session.request(0x01, 0x01, read(256), dest=CELL)
        assert r.data == (2256).to_bytes(2, "big")
        assert anyio.current_time() == pytest.approx(0.1, abs=1e-6)
        assert [f[9] for f in received] == [*range(256), 1]
        assert all(f[3:6] == b"\x02\x02\x00" for f in received)
        stats = session.stats
        assert (stats.completed, stats.end_code_errors) == (256, 1)
        assert (stats.duplicates, stats.unsolicited, stats.late_replies) == (1, 0, 0)


@on_virtual_time
async def test_a_copy_of_a_late_relay_error_finds_its_sid_still_quarantined() -> None:
    """A read to 2.9.0 (SID 0) times out at 0.1 s; its relay error comes 0.4 s late and a
    copy of it 0.3 s after that. At 0.1 s a second read to 2.9.0 got its relay error at
    once: the destination's route answers again, so SID 0's quarantine was to end at
    0.6 s, and the late relay error at 0.4 s did not lengthen it. The copy at 0.7 s then
    answered a read of the gateway's CPU that took SID 0 at 0.65 s (the soak's seed
    40055). A late reply's SID now stays quarantined 0.5 s (or the linger) after it came,
    however soon its quarantine was to end: the read takes SID 1 and gets its words."""
    relay_errors = 0

    def fate(packet: Packet) -> Sequence[float]:
        nonlocal relay_errors
        data = packet.data
        if packet.source[0] != "10.0.0.10" or len(data) < 14:
            return [0.0]
        if data[12] & 0x80:
            relay_errors += 1
            return [0.4, 0.7] if relay_errors == 1 else [0.0]
        return [0.2]

    async with plant_session(fate, timeout=0.1, retries=0) as (session, plant, received):
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read(0), dest=MISSING)
        with pytest.raises(RelayError):
            await session.request(0x01, 0x01, read(0), dest=MISSING)
        await anyio.sleep(0.55)
        start = anyio.current_time()
        assert start == pytest.approx(0.65, abs=1e-6)
        r = await session.request(0x01, 0x01, read(20, 1), timeout=1.0)
        assert r.data == (120).to_bytes(2, "big")
        assert anyio.current_time() - start == pytest.approx(0.2, abs=1e-6)
        sent = [(f[3:6], f[9]) for f in received]
        assert sent == [(b"\x02\x09\x00", 0), (b"\x02\x09\x00", 1), (b"\x01\x0a\x00", 1)]
        assert plant.counts["refused:0205"] == 2
        stats = session.stats
        assert (stats.completed, stats.end_code_errors, stats.timeouts) == (1, 1, 1)
        assert (stats.late_replies, stats.duplicates, stats.unsolicited) == (2, 0, 0)


@pytest.mark.parametrize(
    ("dest", "word"),
    [(GATEWAY, 356), (CELL, 2256)],
    ids=["the-relay-s-own-cpu", "the-cell-again"],
)
@on_virtual_time
async def test_a_relay_error_later_than_the_evidence_reaches_no_request_that_reused_its_sid(
    dest: FinsAddress, word: int
) -> None:
    """The cell (2.2.0) is down: the gateway answers a read of it (SID 0) with 0205 and bit
    15, and the network delays that relay error 0.8 s. The read times out at 0.1 s (SID 0
    quarantined); the cell is up again and answers the next reads (SIDs 1 to 255) at once:
    the destination answers requests sent after SID 0 was given up on, so SID 0's
    quarantine ends 0.5 s later, at 0.6 s (the evidence rule: the cell's own reply to the
    older read could only come as a reordered datagram). The relay error comes from the
    relay, on the relay's timer, not from the cell: at 0.8 s it found a read that took SID 0
    at 0.7 s, whose reply takes 0.2 s (of the gateway's CPU, whose key the relay error
    carries exactly; or of the cell, by SID and command code), and raised the cell's 0205
    to it (the soak's seed 50135). A SID whose quarantine ended on that evidence is now in
    doubt for a relay error under its number and command code until the quarantine's full
    term: the relay error is taken for the older read's (counted as late), and the read
    gets its own words at 0.9 s."""
    relay_errors = 0

    def fate(packet: Packet) -> Sequence[float]:
        nonlocal relay_errors
        data = packet.data
        if packet.source[0] != "10.0.0.10" or len(data) < 14:
            return [0.0]
        if data[12] & 0x80:
            relay_errors += 1
            return [0.8]
        return [0.2] if data[14:] == word.to_bytes(2, "big") else [0.0]

    async with plant_session(fate, timeout=0.1, retries=0) as (session, plant, received):
        plant.station("cell").state = StationState.DOWN
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read(0), dest=CELL)
        plant.station("cell").state = StationState.UP
        for n in range(1, 256):  # the cell's SIDs come round to 0 again
            r = await session.request(0x01, 0x01, read(n), dest=CELL)
            assert r.data == (2000 + n).to_bytes(2, "big")
        assert anyio.current_time() == pytest.approx(0.1, abs=1e-6)
        await anyio.sleep(0.6)
        r = await session.request(0x01, 0x01, read(256), dest=dest, timeout=1.0)
        assert r.data == word.to_bytes(2, "big")
        assert anyio.current_time() == pytest.approx(0.9, abs=1e-6)
        assert relay_errors == 1
        assert plant.counts["refused:0205"] == 1
        sent = [(f[3:6], f[9]) for f in received]
        assert sent == [
            *((b"\x02\x02\x00", n) for n in range(256)),
            (bytes((dest.network, dest.node, 0)), 0),  # SID 0 again, after its quarantine
        ]
        stats = session.stats
        assert (stats.completed, stats.timeouts, stats.end_code_errors) == (256, 1, 0)
        assert (stats.late_replies, stats.duplicates, stats.unsolicited) == (1, 0, 0)


@on_virtual_time
async def test_a_late_relay_error_is_no_round_trip_of_the_link() -> None:
    """A read of 2.9.0 (SID 0) times out at 0.1 s; its relay error comes at 2 s, from the
    relay's timer, not from the destination: it ends SID 0's quarantine (late), and
    taught the link's slowest round trip, 2 s, so that a quarantine ended by the evidence
    that the destination answers lasted 4 s after its request was sent (soak seed 50135,
    relay errors 1.2 to 5.8 s late: every SID quarantined in the recovery phase). A read of
    the cell (SID 1) at 2.1 s whose reply is lost times out at 2.2 s; the cell answers the
    next read at once, so SID 1's quarantine ends at 2.7 s: at 2.75 s 256 reads of the
    cell take every SID in turn, SID 1 included."""

    def fate(packet: Packet) -> Sequence[float]:
        data = packet.data
        if packet.source[0] != "10.0.0.10" or len(data) < 14:
            return [0.0]
        if data[12] & 0x80:
            return [2.0]
        return [] if data[14:] == (2005).to_bytes(2, "big") else [0.0]

    async with plant_session(fate, timeout=0.1, retries=0) as (session, plant, received):
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read(0), dest=MISSING)
        await anyio.sleep(1.8)
        assert session.stats.late_replies == 0
        await anyio.sleep(0.2)
        assert session.stats.late_replies == 1
        with pytest.raises(FinsTimeout):
            await session.request(0x01, 0x01, read(5), dest=CELL)
        r = await session.request(0x01, 0x01, read(6), dest=CELL)
        assert r.data == (2006).to_bytes(2, "big")
        assert anyio.current_time() == pytest.approx(2.2, abs=1e-6)
        await anyio.sleep(0.55)
        for n in range(7, 7 + 256):
            r = await session.request(0x01, 0x01, read(n), dest=CELL)
            assert r.data == (2000 + n).to_bytes(2, "big")
        sids = [f[9] for f in received]
        assert sids[:3] == [0, 1, 2]
        assert sorted(sids[3:]) == list(range(256))
        stats = session.stats
        assert (stats.completed, stats.timeouts, stats.late_replies) == (257, 2, 1)
        assert plant.counts["refused:0205"] == 1
