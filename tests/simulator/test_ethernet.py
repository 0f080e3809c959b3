"""An Ethernet Unit's FINS address conversion (simulator/ethernet.py): the internal table
per method, what it learns, where the UDP server's replies go, over real loopback sockets
and over the in-memory network; bytes and addresses asserted."""

from __future__ import annotations

import anyio
import pytest
import trio
import trio.testing

from aiofins.memnet import MemoryNetwork
from aiofins.protocol.errors import FinsTimeout
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.simulator import (
    AddressConversion,
    Delay,
    EthernetUnit,
    FaultPlan,
    FaultRule,
    VirtualPLC,
    run_simulator,
)
from aiofins.simulator.ethernet import node_of
from aiofins.transport import UdpTransport

from ..virtual_time import VIRTUAL_BACKENDS, run_on_virtual_time

DYNAMIC = AddressConversion.AUTOMATIC_DYNAMIC
STATIC = AddressConversion.AUTOMATIC_STATIC
TABLE = AddressConversion.IP_ADDRESS_TABLE
COMBINED = AddressConversion.COMBINED


def command(sa1: int, da1: int = 10, sid: int = 1) -> bytes:
    """0101 read of D0, one word, from node ``sa1`` to node ``da1``."""
    return bytes([0x80, 0, 2, 0, da1, 0, 0, sa1, 0, sid, 0x01, 0x01, 0x82, 0, 0, 0, 0, 1])


def reply_to(sa1: int) -> bytes:
    """A reply's header to node ``sa1`` (DA1 = the command's SA1)."""
    return bytes([0xC0, 0, 2, 0, sa1, 0, 0, 10, 0, 1, 0x01, 0x01, 0, 0, 0, 0])


# -- the model ------------------------------------------------------------------------------


def test_the_node_of_an_address_is_its_host_number() -> None:
    assert node_of("192.168.250.1") == 1
    assert node_of("192.168.250.254") == 254
    assert node_of("10.0.1.7", "255.255.0.0") == 0x107  # (no FINS node: above 254)
    assert EthernetUnit("192.168.250.10").node == 10
    with pytest.raises(ValueError, match=r"host number \(10 for 192\.168\.250\.10\), not 3"):
        EthernetUnit("192.168.250.10", node=3)
    with pytest.raises(ValueError, match="host number 263"):
        EthernetUnit("10.0.1.7", subnet_mask="255.255.0.0")
    with pytest.raises(ValueError, match="name the unit's node"):
        EthernetUnit("10.0.1.7", conversion=TABLE)
    assert EthernetUnit("10.0.1.7", subnet_mask="255.255.0.0", conversion=TABLE, node=5).node == 5


def test_automatic_dynamic_replies_where_the_node_s_last_command_came_from() -> None:
    unit = EthernetUnit("192.168.250.10")
    assert unit.address_of(2) == ("192.168.250.2", 9600)  # before any command
    assert unit.received(command(2), ("192.168.250.77", 50001)) == 2
    assert unit.destination(reply_to(2)) == ("192.168.250.77", 50001)
    unit.received(command(2), ("192.168.250.77", 50002))  # another socket, the same SA1
    assert unit.destination(reply_to(2)) == ("192.168.250.77", 50002)  # steals the reply
    assert unit.address_of(3) == ("192.168.250.3", 9600)
    unit.restart()
    assert unit.address_of(2) == ("192.168.250.2", 9600)


def test_automatic_static_replies_to_the_fins_port_of_the_derived_address() -> None:
    unit = EthernetUnit("192.168.250.10", conversion=STATIC, fins_port=9601)
    unit.received(command(2), ("192.168.250.77", 50001))
    assert unit.destination(reply_to(2)) == ("192.168.250.2", 9601)


def test_an_ip_address_table_replies_to_listed_nodes_at_the_fins_port_and_learns_the_others() -> (
    None
):
    unit = EthernetUnit("10.1.1.1", conversion=TABLE, node=1, ip_table={2: "10.9.9.9"})
    assert unit.address_of(2) == ("10.9.9.9", 9600)
    assert unit.address_of(3) is None  # 0.0.0.0: nowhere
    assert unit.destination(reply_to(3)) is None
    assert unit.unaddressed == 1
    unit.received(command(2), ("10.1.1.2", 50001))  # listed: never changed
    unit.received(command(3), ("10.1.1.3", 50003))  # not listed: learnt
    assert unit.destination(reply_to(2)) == ("10.9.9.9", 9600)
    assert unit.destination(reply_to(3)) == ("10.1.1.3", 50003)


def test_combined_falls_back_to_automatic_and_dynamic_changes_may_be_prohibited() -> None:
    unit = EthernetUnit(
        "10.1.1.1", conversion=COMBINED, node=1, ip_table={2: "10.9.9.9"}, change_dynamically=False
    )
    assert unit.address_of(2) == ("10.9.9.9", 9600)
    assert unit.address_of(3) == ("10.1.1.3", 9600)
    unit.received(command(3), ("10.1.1.3", 50003))
    assert unit.address_of(3) == ("10.1.1.3", 9600)  # prohibited: as at start
    assert not unit.learns(3) and EthernetUnit("10.1.1.1", conversion=COMBINED, node=1).learns(3)


def test_a_frame_shorter_than_a_header_teaches_nothing_and_goes_nowhere() -> None:
    unit = EthernetUnit("192.168.250.10")
    assert unit.received(b"\x80\x00", ("192.168.250.2", 1)) is None
    assert unit.destination(b"\xc0") is None and unit.unaddressed == 1


# -- the UDP server over real sockets -------------------------------------------------------


@pytest.mark.anyio
async def test_a_static_unit_answers_only_a_client_bound_to_the_fins_port(
    anyio_backend: object,
) -> None:
    """Unit 127.0.0.10 (node 10), static conversion, its FINS port P (the server's): a client
    at 127.0.0.2 with source node 2 bound to an ephemeral port times out; bound to port P it
    reads the word."""
    plc = VirtualPLC(node=10)
    plc.memory.write_words(0x82, 0, [0x4321])
    unit = EthernetUnit("127.0.0.10", conversion=STATIC)
    async with run_simulator(plc, udp=("127.0.0.10", 0), ethernet=unit) as sim:
        port = unit.fins_port = sim.udp_port  # (the unit's setup: its FINS port)
        unit.restart()
        assert unit.address_of(2) == ("127.0.0.2", port)
        source, dest = FinsAddress(0, 2, 0), FinsAddress(0, 10, 0)
        ephemeral = UdpTransport("127.0.0.10", port, local_host="127.0.0.2")
        async with Session(ephemeral, source=source, dest=dest, timeout=0.3, retries=0) as s:
            with pytest.raises(FinsTimeout):
                await s.request(0x01, 0x01, bytes.fromhex("820000000001"))
        assert unit.unaddressed == 0  # (sent to 127.0.0.2:P, where nobody listened)
        fixed = UdpTransport("127.0.0.10", port, local_host="127.0.0.2", local_port=port)
        async with Session(fixed, source=source, dest=dest, timeout=10.0) as s:
            r = await s.request(0x01, 0x01, bytes.fromhex("820000000001"))
            assert r.data == b"\x43\x21"
            assert r.frame[:10] == bytes.fromhex("C0 00 02 00 02 00 00 0A 00") + r.frame[9:10]


@pytest.mark.anyio
async def test_a_dynamic_unit_answers_the_port_a_command_came_from(anyio_backend: object) -> None:
    plc = VirtualPLC(node=1)
    plc.memory.write_words(0x82, 0, [0x0BAD])
    unit = EthernetUnit("127.0.0.1")
    async with run_simulator(plc, udp=("127.0.0.1", 0), ethernet=unit) as sim:
        transport = UdpTransport("127.0.0.1", sim.udp_port)
        source, dest = FinsAddress(0, 2, 0), FinsAddress(0, 1, 0)
        async with Session(transport, source=source, dest=dest, timeout=10.0) as s:
            r = await s.request(0x01, 0x01, bytes.fromhex("820000000001"))
            assert r.data == b"\x0b\xad"
            assert unit.address_of(2) == transport.local_address


# -- over the in-memory network -------------------------------------------------------------


def test_on_the_network_a_write_without_a_reply_still_executes_and_times_out_exactly() -> None:
    """Static unit 10.0.0.10; the client at 10.0.0.2 from an ephemeral port: its write is
    executed, the reply goes to 10.0.0.2:9600 where nobody listens (unreachable), the call
    fails at exactly its timeout; from port 9600 the same write is answered at once."""
    plc = VirtualPLC(node=10)
    unit = EthernetUnit("10.0.0.10", conversion=STATIC)
    out: list[object] = []

    async def main() -> None:
        async with (
            MemoryNetwork() as net,
            run_simulator(plc, udp=("10.0.0.10", 9600), network=net, ethernet=unit),
        ):
            for local_port in (0, 9600):
                transport = UdpTransport(
                    "10.0.0.10", local_host="10.0.0.2", network=net, local_port=local_port
                )
                async with Session(
                    transport,
                    source=FinsAddress(0, 2, 0),
                    dest=FinsAddress(0, 10, 0),
                    timeout=0.5,
                    retries=0,
                ) as s:
                    start = trio.current_time()
                    try:
                        await s.request(0x01, 0x02, bytes.fromhex("8200000000010007"))
                    except FinsTimeout:
                        out.append(("timeout", trio.current_time() - start))
                    else:
                        out.append(("ok", trio.current_time() - start))
                    out.append(plc.memory.read_words(0x82, 0, 1))
            out.append(net.stats.unreachable)

    trio.run(main, clock=trio.testing.MockClock(autojump_threshold=0))
    assert out == [("timeout", 0.5), [7], ("ok", 0.0), [7], 1]


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_on_the_network_two_sockets_sharing_a_node_steal_each_other_s_replies(
    backend: str,
) -> None:
    """Replies 0.1 s late: the second socket's command (same source node) arrives before
    the first one's reply is sent, so a dynamic unit sends both replies to the second (at
    exactly t = 0.1 s)."""
    out: list[tuple[float, tuple[str, int], str]] = []

    async def main() -> None:
        async with (
            MemoryNetwork() as net,
            run_simulator(
                VirtualPLC(node=10),
                udp=("10.0.0.10", 9600),
                network=net,
                ethernet=EthernetUnit("10.0.0.10"),
                faults=FaultPlan(FaultRule(delay=Delay(0.1, 0.1))),
            ),
        ):
            first = net.datagram_socket("10.0.0.2", 50001)
            second = net.datagram_socket("10.0.0.2", 50002)
            first.sendto(command(2, sid=1), ("10.0.0.10", 9600))
            second.sendto(command(2, sid=2), ("10.0.0.10", 9600))
            for _ in range(2):
                data, source = await second.receive()
                out.append((anyio.current_time(), source, data[:10].hex()))
            with pytest.raises(BlockingIOError):
                first.recv(100)

    run_on_virtual_time(main, backend)
    assert [(round(t, 6), source, data) for t, source, data in sorted(out)] == [
        (0.1, ("10.0.0.10", 9600), "c00002000200000a0001"),
        (0.1, ("10.0.0.10", 9600), "c00002000200000a0002"),
    ]
