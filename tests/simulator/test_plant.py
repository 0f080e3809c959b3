"""The plant: routing tables, relaying, GCT, relay errors and size limits (manual 5-1)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.endcodes import EndCode
from aiofins.protocol.errors import CommandError
from aiofins.protocol.header import FinsAddress, Header, ResponseFrame, build_command
from aiofins.protocol.limits import NetworkType
from aiofins.simulator.ethernet import AddressConversion, EthernetUnit
from aiofins.simulator.plant import (
    Network,
    Plant,
    RoutingTables,
    Station,
    StationState,
    Unit,
)
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.state import Mode

from ..protocol.test_tshark import TSHARK, _warnings, pcap, run_tshark, udp_packet

CLIENT = ("127.0.0.1", 40000)


def three_networks() -> Plant:
    """Ethernet 1 (gateway A node 10) - Controller Link 2 (A node 1, B node 2) - SYSMAC
    LINK 3 (B node 3, C node 5). C is two networks away from a client on network 1."""
    a_eth = Unit(0x10, 1, 10, host="127.0.0.10", port=0)
    a = Station(
        "A",
        VirtualPLC(network=1, node=10, mode=Mode.RUN),
        [a_eth, Unit(0x11, 2, 1)],
        RoutingTables({0x10: 1, 0x11: 2}, {3: (2, 2)}),
    )
    b = Station(
        "B",
        VirtualPLC(network=2, node=2, mode=Mode.RUN),
        [Unit(0x10, 2, 2), Unit(0x11, 3, 3)],
        RoutingTables({0x10: 2, 0x11: 3}, {1: (2, 1)}),
    )
    c = Station(
        "C",
        VirtualPLC(network=3, node=5, mode=Mode.RUN),
        [Unit(0x10, 3, 5)],
        RoutingTables({0x10: 3}, {1: (3, 3), 2: (3, 3)}),
    )
    d = Station(  # a PLC on the Ethernet without routing tables
        "D", VirtualPLC(network=1, node=20, mode=Mode.RUN), [Unit(0x10, 1, 20, host="127.0.0.20")]
    )
    c.plc.write("D0", [0x1234, 0x5678])
    b.plc.write("D0", [0x0B0B])
    return Plant(
        [
            Network(1, NetworkType.ETHERNET),
            Network(2, NetworkType.CONTROLLER_LINK),
            Network(3, NetworkType.SYSMAC_LINK),
        ],
        [a, b, c, d],
    )


def read_d0(dest: str, count: int = 2, *, src: str = "1.254.0", gct: int = 2) -> bytes:
    params = bytes((0x82, 0, 0, 0, count >> 8, count & 0xFF))
    return build_command(FinsAddress.parse(dest), FinsAddress.parse(src), 7, 1, 1, params, gct=gct)


def send(plant: Plant, frame: bytes, station: str = "A") -> ResponseFrame:
    unit = plant.station(station).units[0]
    out = plant.receive(unit, frame, *CLIENT)
    assert len(out) == 1, plant.counts
    assert (out[0].host, out[0].port) == CLIENT and out[0].unit is unit
    return ResponseFrame.decode(out[0].frame)


def test_a_read_two_networks_away_crosses_two_gateways() -> None:
    plant = three_networks()
    reply = send(plant, read_d0("3.5.0"))
    assert reply.end_code == EndCode(0) and reply.data == bytes.fromhex("12345678")
    assert reply.header.source == FinsAddress(3, 5, 0)
    assert reply.header.destination == FinsAddress(1, 254, 0)
    # GCT on the wire, hop by hop: 2 on network 1, 1 on 2, 0 on 3; the reply starts at 2
    hops = [(h.network, h.frame[0], h.frame[2]) for h in plant.trace]
    assert hops == [
        (1, 0x80, 2), (2, 0x80, 1), (3, 0x80, 0),
        (3, 0xC0, 2), (2, 0xC0, 1), (1, 0xC0, 0),
    ]  # fmt: skip
    assert plant.counts["relayed"] == 4 and plant.counts["delivered"] == 1


def test_one_network_away_and_the_gateway_itself() -> None:
    plant = three_networks()
    assert send(plant, read_d0("2.2.0", 1)).data == bytes.fromhex("0B0B")
    assert send(plant, read_d0("0.0.0", 1)).header.source == FinsAddress(0, 10, 0)
    assert send(plant, read_d0("1.10.0", 1)).end_code == EndCode(0)


def test_writes_are_routed() -> None:
    plant = three_networks()
    frame = build_command(
        FinsAddress(3, 5, 0), FinsAddress(1, 254, 0), 9, 1, 2, bytes.fromhex("8200640000010102")
    )
    assert send(plant, frame).end_code == EndCode(0)
    assert plant.station("C").plc.read("D100") == [0x0102]


@pytest.mark.parametrize(
    ("dest", "gct", "code", "relay"),
    [
        ("4.1.0", 2, 0x0501, (1, 10)),  # A has no relay entry for network 4
        ("2.9.0", 2, 0x0205, (1, 10)),  # no node 9 on network 2: nothing answers A
        ("3.9.0", 2, 0x0205, (2, 2)),  # no node 9 on network 3: B names itself
        ("3.5.0", 1, 0x0504, (2, 2)),  # GCT 1: A takes it to 0, B may not forward
        ("2.2.0", 0, 0x0504, (1, 10)),
    ],
)
def test_relay_errors_name_the_relay_point(
    dest: str, gct: int, code: int, relay: tuple[int, int]
) -> None:
    plant = three_networks()
    reply = send(plant, read_d0(dest, gct=gct))
    assert reply.end_code.relay_error and reply.end_code.code == code
    assert reply.relay == relay
    assert reply.header.source == FinsAddress(relay[0], relay[1], 0)
    assert plant.counts[f"refused:{code:04x}"] == 1


def test_a_plc_without_routing_tables_answers_0502() -> None:
    plant = three_networks()
    reply = send(plant, read_d0("3.5.0"), station="D")
    assert (reply.end_code.raw, reply.relay) == (0x8502, (1, 20))
    assert send(plant, read_d0("1.20.0", 1), station="D").end_code == EndCode(0)


@pytest.mark.parametrize(("state", "code"), [("busy", 0x0204), ("down", 0x0205)])
def test_a_busy_or_silent_next_hop(state: str, code: int) -> None:
    plant = three_networks()
    plant.station("B").state = StationState(state)
    reply = send(plant, read_d0("3.5.0"))
    assert (reply.end_code.code, reply.relay) == (code, (1, 10))


def test_a_command_too_long_for_sysmac_link_is_refused_by_the_relay() -> None:
    """Ours: 1001 with bit 15 from the relay that would put it on the smaller network."""
    plant = three_networks()
    words = 268  # 8 + 536 = 544 parameter bytes: over SYSMAC LINK's 540
    params = bytes.fromhex("820000") + b"\x00" + words.to_bytes(2, "big") + bytes(2 * words)
    frame = build_command(FinsAddress(3, 5, 0), FinsAddress(1, 254, 0), 3, 1, 2, params)
    reply = send(plant, frame)
    assert (reply.end_code.raw, reply.relay) == (0x9001, (2, 2))
    ok = build_command(FinsAddress(2, 2, 0), FinsAddress(1, 254, 0), 4, 1, 2, params)
    assert send(plant, ok).end_code == EndCode(0)  # Controller Link carries 2,000 bytes


def test_a_response_too_long_for_sysmac_link_is_110b() -> None:
    plant = three_networks()
    assert len(send(plant, read_d0("3.5.0", 269)).data) == 538
    reply = send(plant, read_d0("3.5.0", 270))
    assert reply.end_code.raw == 0x110B and reply.data == b""
    assert len(send(plant, read_d0("2.2.0", 999)).data) == 1998


def test_a_routed_request_without_its_source_network_gets_no_reply() -> None:
    """SNA 0 means "my local network" to the destination too: C answers on network 3,
    where node 254 is not."""
    plant = three_networks()
    assert (
        plant.receive(plant.station("A").units[0], read_d0("3.5.0", src="0.254.0"), *CLIENT) == []
    )
    assert plant.counts["dropped:0205"] == 1
    assert plant.station("C").plc.frames_handled == 1


def test_table_and_static_conversion_answer_to_the_fins_port() -> None:
    """The Ethernet unit's address conversion (simulator/ethernet.py) decides where a reply
    leaves the plant: a node in the IP address table at its address, port 9600; automatic
    static conversion at the unit's subnet + the node, port 9600."""
    plant = three_networks()
    unit = plant.station("A").units[0]
    unit.ethernet = EthernetUnit(
        "127.0.0.10", conversion=AddressConversion.IP_ADDRESS_TABLE, ip_table={254: "127.0.0.9"},
        node=10,
    )  # fmt: skip
    (out,) = plant.receive(unit, read_d0("0.10.0", 1), *CLIENT)
    assert (out.host, out.port) == ("127.0.0.9", 9600)
    (out,) = plant.receive(unit, read_d0("0.10.0", 1, src="1.77.0"), *CLIENT)
    assert (out.host, out.port) == CLIENT  # not in the table: learnt from its command
    unit.ethernet = EthernetUnit("127.0.0.10", conversion=AddressConversion.AUTOMATIC_STATIC)
    (out,) = plant.receive(unit, read_d0("0.10.0", 1, src="1.77.0"), *CLIENT)
    assert (out.host, out.port) == ("127.0.0.77", 9600)
    with pytest.raises(CommandError, match="host number"):
        Unit(0x10, 1, 10, host="127.0.0.1")  # automatic conversion: node 1 at 127.0.0.1


def test_tables_are_checked_against_the_manuals_rules() -> None:
    eth = Network(1, NetworkType.ETHERNET)
    cl = Network(2, NetworkType.CONTROLLER_LINK)

    def station(tables: RoutingTables) -> Station:
        return Station("X", VirtualPLC(), [Unit(0x10, 1, 1)], tables)

    with pytest.raises(CommandError, match="network 2, which it does not have"):
        Plant([eth, cl], [station(RoutingTables({0x10: 2}))])
    with pytest.raises(CommandError, match="network 1 is local"):
        Plant([eth, cl], [station(RoutingTables({0x10: 1}, {1: (1, 5)}))])
    with pytest.raises(CommandError, match="not in its local network table"):
        Plant([eth, cl], [station(RoutingTables({0x10: 1}, {3: (2, 5)}))])
    with pytest.raises(CommandError, match="both"):
        Plant([eth], [station(RoutingTables({0x10: 1})), station(RoutingTables({0x10: 1}))])
    with pytest.raises(CommandError, match="which the plant does not have"):
        Plant([cl], [station(RoutingTables({}))])


def test_garbage_and_responses_are_counted_not_raised() -> None:
    plant = three_networks()
    unit = plant.station("A").units[0]
    assert plant.receive(unit, b"\x80\x00", *CLIENT) == []
    stray = (
        Header(FinsAddress(1, 10, 0), FinsAddress(1, 254, 0), icf=0xC0).encode()
        + b"\x01\x01\x00\x00"
    )
    assert plant.receive(unit, stray, *CLIENT) == []
    assert plant.counts["dropped:malformed"] == 1
    assert plant.counts["dropped:response-for-a-plc"] == 1


def test_tshark_decodes_every_hop(tmp_path: Path) -> None:
    """Wireshark's dissector reads each frame as it travelled on each network: a read and a
    write two networks away, command and response, with the GCT of that hop."""
    if TSHARK is None:
        pytest.skip("tshark is not installed")
    plant = three_networks()
    send(plant, read_d0("3.5.0", 10))
    write = build_command(
        FinsAddress(3, 5, 0), FinsAddress(1, 254, 0), 8, 1, 2, bytes.fromhex("8200640000010102")
    )
    send(plant, write)
    hops = list(plant.trace)
    assert len(hops) == 12
    path = tmp_path / "hops.pcap"
    path.write_bytes(pcap([udp_packet(h.frame, to_plc=not h.frame[0] & 0x40) for h in hops]))
    rows = run_tshark(path, "udp.port==9600,omron")
    assert len(rows) == 12
    for row, hop in zip(rows, hops, strict=True):
        assert int(row["omron.icf"], 16) == hop.frame[0]
        assert int(row["omron.command"], 16) == (hop.frame[10] << 8) | hop.frame[11]
        assert row["_ws.malformed"] == "" and not _warnings(row), row["_ws.expert.message"]
    assert [h.frame[2] for h in hops[:3]] == [2, 1, 0]


@pytest.mark.parametrize(
    ("kind", "carried"),
    [
        (NetworkType.ETHERNET, 2000),
        (NetworkType.CONTROLLER_LINK, 2000),
        (NetworkType.SYSMAC_LINK, 540),
        (NetworkType.DEVICENET, 540),
        (NetworkType.HOST_LINK, 540),
    ],
)
def test_oversize_frames_per_network_type(kind: NetworkType, carried: int) -> None:
    """A gateway puts on the next network a command of up to its parameter bytes and refuses
    one byte more (ours: 1001 + bit 15, the gateway named); a response longer than the
    network carries is answered 110B by the destination."""
    gateway = Station(
        "G",
        VirtualPLC(network=1, node=10, mode=Mode.RUN),
        [Unit(0x10, 1, 10, host="127.0.0.10"), Unit(0x11, 2, 1)],
        RoutingTables({0x10: 1, 0x11: 2}),
    )
    far = Station("F", VirtualPLC(network=2, node=2, mode=Mode.RUN), [Unit(0x10, 2, 2)],
                  RoutingTables({0x10: 2}, {1: (2, 1)}))  # fmt: skip
    plant = Plant([Network(1, NetworkType.ETHERNET), Network(2, kind)], [gateway, far])
    unit = gateway.units[0]

    def write(size: int) -> ResponseFrame:
        words = (size - 6) // 2  # 0102: 6 bytes of address and count, then the words
        params = bytes.fromhex("820000 00") + words.to_bytes(2, "big") + bytes(2 * words)
        head = Header(FinsAddress(2, 2, 0), FinsAddress(1, 254, 0), sid=1).encode()
        (out,) = plant.receive(unit, head + b"\x01\x02" + params, *CLIENT)
        return ResponseFrame.decode(out.frame)

    assert write(carried).end_code == EndCode(0)
    refused = write(carried + 2)
    assert (refused.end_code.raw, refused.relay) == (0x9001, (1, 10))
    words = carried // 2 - 1  # the most a response of this network holds
    assert len(send(plant, read_d0("2.2.0", words), "G").data) == 2 * words
    if carried == 540:  # (a CPU refuses more than 999 words itself)
        assert send(plant, read_d0("2.2.0", words + 1), "G").end_code.raw == 0x110B


@given(st.binary(max_size=64), st.integers(0, 255), st.integers(0, 7), st.integers(0, 2))
def test_any_datagram_is_routed_or_counted_never_raised(
    tail: bytes, dna: int, dest_node: int, gct: int
) -> None:
    """Whatever reaches a unit: answered, relayed, refused or dropped and counted."""
    plant = three_networks()
    head = bytes((0x80, 0, gct, dna, (10, 0, 1, 2, 3, 5, 9, 255)[dest_node], 0, 1, 254, 0, 7))
    for frame in (tail, head + tail, head + b"\x01\x01" + tail):
        out = plant.receive(plant.station("A").units[0], frame, *CLIENT)
        for datagram in out:
            assert datagram.frame[0] & 0x40  # only responses leave the plant here
    assert sum(plant.counts.values()) >= 1
