"""A client reaching PLCs behind gateways: route limits per destination network, the source
network, relay errors, against the plant of examples/plant.toml served on UDP."""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import pytest

import aiofins
from aiofins.bulk import (
    backup_parameters,
    backup_program,
    download_file,
    restore_parameters,
    restore_program,
    upload_file,
)
from aiofins.protocol.errors import CommandError, FinsTimeout, RelayError
from aiofins.protocol.files import Disk
from aiofins.protocol.limits import NetworkType, limits_for, parse_routes
from aiofins.simulator.ethernet import AddressConversion
from aiofins.simulator.plant import Network, Plant, Station, StationState, Unit
from aiofins.simulator.plantfile import load_plant
from aiofins.simulator.plantserver import serve_plant
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.state import Mode

pytestmark = pytest.mark.anyio

EXAMPLE = Path(__file__).parents[2] / "examples" / "plant.toml"
ROUTES = "2:controller_link,3:sysmac_link"
SYSMAC = limits_for(NetworkType.SYSMAC_LINK)


def example_plant() -> Plant:
    plant = load_plant(str(EXAMPLE))
    plant.station("line").units[0].port = 0  # any free port
    return plant


@asynccontextmanager
async def plant_client(
    query: str = f"source_network=1&routes={ROUTES}", **options: object
) -> AsyncIterator[tuple[Plant, aiofins.Client]]:
    plant = example_plant()
    async with serve_plant(plant) as server:
        port = server.port_of(plant.station("line").units[0])
        url = f"udp://127.0.0.10:{port}?timeout=0.5&{query}"
        async with aiofins.connect(url, retries=0, **options) as plc:  # type: ignore[arg-type]
            yield plant, plc


def largest_on(plant: Plant, network: int) -> int:
    """The largest command parameter (or response data) size seen on ``network``."""
    sizes = [len(h.frame) - (14 if h.frame[0] & 0x40 else 12) for h in plant.trace]
    return max(s for s, h in zip(sizes, plant.trace, strict=True) if h.network == network)


async def test_read_and_write_two_and_three_networks_away() -> None:
    async with plant_client() as (plant, plc):
        assert await plc.read("D0", 2, dest="3.5.0") == [1234, 5678]  # two gateways
        assert await plc.read("D0", 2, dest="2.2.0") == [200, 201]  # one gateway
        assert await plc.read("D0", 2) == [100, 101]  # the gateway itself
        await plc.write("D10", [7, 8, 9], dest="3.5.0")
        assert plant.station("press").plc.read("D10", 3) == [7, 8, 9]
        assert await plc.read_value("D10", "uint32", dest="3.5.0") == (8 << 16) | 7
        # the source network went out: the reply came back over both gateways
        gcts = [(h.network, h.frame[2]) for h in plant.trace if h.frame[3] == 3][:3]
        assert gcts == [(1, 2), (2, 1), (3, 0)]


async def test_a_client_for_a_plc_behind_two_gateways() -> None:
    async with plant_client(dest="3.5.0") as (plant, plc):
        assert plc.limits == SYSMAC  # its own route's limits
        words = list(range(600))
        await plc.write("D100", words, allow_split=True)
        assert await plc.read("D100", 600) == words
        assert largest_on(plant, 3) <= 540


async def test_without_a_source_network_a_routed_reply_is_lost() -> None:
    async with plant_client(f"routes={ROUTES}", breaker_threshold=0) as (plant, plc):
        with pytest.raises(FinsTimeout, match=r"source network 0.*source_network=N"):
            await plc.read("D0", dest="3.5.0")
        with pytest.raises(FinsTimeout, match="source_network=N"):
            await plc.read("D0", 300, dest="3.5.0")  # two frames
        with pytest.raises(FinsTimeout, match="source_network=N"):
            await plc.cpu_unit_status_read(dest="3.5.0")
        assert plant.station("press").plc.frames_handled == 4
        assert plant.counts["dropped:0205"] == 4
        assert await plc.read("D0", 1) == [100]  # unrouted needs none


@pytest.mark.parametrize(
    ("dest", "change", "code", "relay"),
    [
        ("4.5.0", None, 0x0501, (1, 10)),
        ("2.9.0", None, 0x0205, (1, 10)),
        ("3.9.0", None, 0x0205, (2, 2)),
        ("3.5.0", "busy", 0x0204, (1, 10)),
        ("3.5.0", "down", 0x0205, (1, 10)),
    ],
)
async def test_relay_errors_are_typed_and_name_the_relay(
    dest: str, change: str | None, code: int, relay: tuple[int, int]
) -> None:
    async with plant_client() as (plant, plc):
        if change:
            plant.station("cell").state = StationState(change)
        with pytest.raises(RelayError) as info:
            await plc.read("D0", dest=dest)
        assert info.value.end_code.code == code
        assert (info.value.network, info.value.node) == relay


async def test_too_many_relays_with_gct_1() -> None:
    async with plant_client(gct=1) as (_, plc):
        assert await plc.read("D0", dest="2.2.0") == [200]
        with pytest.raises(RelayError) as info:
            await plc.read("D0", dest="3.5.0")
        assert (info.value.end_code.code, info.value.network, info.value.node) == (0x0504, 2, 2)


async def test_a_frame_too_long_for_the_route_is_refused_by_the_relay() -> None:
    """A client told the wrong route sends 300 words towards SYSMAC LINK: the cell gateway
    refuses it with our 1001 + bit 15; a read answers 110B from the destination."""
    async with plant_client("source_network=1&routes=3:ethernet") as (plant, plc):
        with pytest.raises(RelayError) as info:
            await plc.write("D0", list(range(300)), dest="3.5.0")
        assert (info.value.end_code.code, info.value.network, info.value.node) == (0x1001, 2, 2)
        with pytest.raises(aiofins.EndCodeError) as read_info:
            await plc.read("D0", 300, dest="3.5.0")
        assert read_info.value.end_code.code == 0x110B
        assert plant.station("press").plc.read("D0", 2) == [1234, 5678]


async def test_every_chunked_command_keeps_to_its_destinations_route() -> None:
    """The same client: Ethernet-sized frames to the gateway, SYSMAC LINK-sized to the press."""
    async with plant_client() as (plant, plc):
        assert len(await plc.read("D0", 999)) == 999  # one frame to the gateway
        assert largest_on(plant, 1) == 1998
        plant.trace.clear()
        assert len(await plc.read("D0", 999, dest="3.5.0")) == 999  # 4 frames of <= 269
        assert largest_on(plant, 3) == 538
        replies = [h for h in plant.trace if h.network == 3 and h.frame[0] & 0x40]
        assert len(replies) == 4
        with pytest.raises(CommandError, match="267"):
            await plc.write("D0", [1] * 268, dest="3.5.0")  # would need two frames
        # 0104: 100 elements go to the gateway in one frame, not to the press (89)
        addresses = [f"D{i}" for i in range(100)]
        assert len((await plc.multiple_memory_area_read(addresses)).items) == 100
        with pytest.raises(CommandError, match="100 elements; this route carries 89"):
            await plc.multiple_memory_area_read(addresses, dest="3.5.0")
        assert len((await plc.multiple_memory_area_read(addresses[:89], dest="3.5.0")).items) == 89
        with pytest.raises(CommandError, match="parameter_read_words"):
            await plc.parameter_area_read("plc_setup", 0, 300, dest="3.5.0")
        with pytest.raises(CommandError, match="program_read_bytes"):
            await plc.program_area_read(0, 992, dest="3.5.0")
        with pytest.raises(CommandError, match="parameter bytes"):
            await plc.execute(0x01, 0x02, bytes(600), dest="3.5.0")
        with pytest.raises(CommandError, match="548 data bytes; this route carries 538"):
            await plc.single_file_read("card", "A.TXT", 0, 538, dest="3.5.0")


async def test_bulk_transfers_to_a_plc_behind_two_gateways() -> None:
    async with plant_client(dest="3.5.0") as (plant, plc):
        press = plant.station("press").plc
        press.mode = Mode.PROGRAM
        program = bytes(range(256)) * 8
        await restore_program(plc, program)
        assert (await backup_program(plc))[: len(program)] == program
        backup = await backup_parameters(plc)
        await restore_parameters(plc, backup)
        data = bytes(range(256)) * 6
        await upload_file(plc, Disk.MEMORY_CARD, "DATA.BIN", data)
        assert await download_file(plc, Disk.MEMORY_CARD, "DATA.BIN") == data
        plan = plc.compile_tags({f"t{i}": f"D{i * 20}" for i in range(120)}, max_gap=0)
        assert max(len(frame) for frame in plan.multiple) <= 89
        assert len(await plc.read_tags(plan)) == 120
        assert largest_on(plant, 3) <= 540
        assert all(len(h.frame) <= 12 + 540 for h in plant.trace if h.network == 3)


async def test_routes_and_source_network_in_connect_and_pool() -> None:
    async with plant_client("", source_network=1, routes={3: NetworkType.SYSMAC_LINK}) as (
        _,
        plc,
    ):
        assert plc.session.source.network == 1
        assert plc.route_to("3.5.0") == SYSMAC and plc.route_to("2.2.0") == limits_for()
        assert await plc.read("D0", 2, dest="3.5.0") == [1234, 5678]
    plant = example_plant()
    async with serve_plant(plant) as server:
        port = server.port_of(plant.station("line").units[0])
        pool = aiofins.Pool(source_network=1, routes=ROUTES)
        async with pool, pool.client(f"udp://127.0.0.10:{port}?dest=3.5.0") as plc:
            assert plc.limits == SYSMAC
            assert await plc.read("D0", 2) == [1234, 5678]


def test_route_maps_are_checked() -> None:
    assert parse_routes("3:controller_link+sysmac_link")[3] == SYSMAC
    assert parse_routes({2: "serial"})[2].memory_read_words == 269
    for bad, words in [
        ("3", "NETWORK:TYPE"),
        ("0:ethernet", "1..127"),
        ("3:token_ring", "unknown network type"),
        ("3:ethernet,3:sysmac_link", "twice"),
    ]:
        with pytest.raises(CommandError, match=words):
            parse_routes(bad)
    with pytest.raises(CommandError, match="routes"):
        aiofins.endpoint.parse_endpoint("udp://h?routes=3")
    key = aiofins.endpoint.parse_endpoint("udp://h?routes=3:SYSMAC_LINK,2:controller_link").key
    assert key == "udp://h:9600?routes=2:controller_link,3:sysmac_link"


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


async def test_local_port_for_a_plc_with_an_ip_address_table() -> None:
    """The PLC answers node 1 (us, from 127.0.0.1) at the table's address and the FINS port
    only: a client gets its replies when it binds that port, on connect(), in the URL and in
    a Pool; without it, none."""
    fins_port = free_udp_port()  # stands for 9600, which a test may not take on loopback
    unit = Unit(
        0x10, 1, 10, host="127.0.0.10", port=0, conversion=AddressConversion.IP_ADDRESS_TABLE,
        ip_table={1: "127.0.0.1"}, fins_port=fins_port,
    )  # fmt: skip
    plc = VirtualPLC(network=1, node=10, mode=Mode.RUN)
    plc.write("D0", [42])
    plant = Plant([Network(1, NetworkType.ETHERNET)], [Station("table", plc, [unit])])
    async with serve_plant(plant) as server:
        url = f"udp://127.0.0.10:{server.port_of(unit)}?timeout=0.3&src=0.1.0"
        async with aiofins.connect(url, local_port=fins_port) as client:
            assert client.session.transport.local_address[1] == fins_port  # type: ignore[attr-defined]
            assert await client.read("D0") == [42]
        async with aiofins.connect(f"{url}&local_port={fins_port}") as client:
            assert await client.read("D0") == [42]
        async with aiofins.Pool(local_port=fins_port) as pool, pool.client(url) as client:
            assert await client.read("D0") == [42]
        async with aiofins.connect(url, retries=0) as client:
            with pytest.raises(FinsTimeout):
                await client.read("D0")  # the reply went to the FINS port
        with pytest.raises(CommandError, match="max_sid_spaces must be 1"):
            async with aiofins.connect(url, local_port=fins_port, max_sid_spaces=2):
                pass


async def test_one_fixed_port_for_several_plcs_with_ip_address_tables() -> None:
    """Two PLCs answering to our FINS port: one client each, both bound to that port; each
    reply reaches the socket connected to the PLC that sent it."""
    fins_port = free_udp_port()
    units, stations = [], []
    for octet in (11, 12):
        unit = Unit(
            0x10, 1, octet, host=f"127.0.0.{octet}", port=0, ip_table={1: "127.0.0.1"},
            conversion=AddressConversion.IP_ADDRESS_TABLE, fins_port=fins_port,
        )  # fmt: skip
        plc = VirtualPLC(network=1, node=octet, mode=Mode.RUN)
        plc.write("D0", [octet])
        units.append(unit)
        stations.append(Station(f"plc{octet}", plc, [unit]))
    plant = Plant([Network(1, NetworkType.ETHERNET)], stations)
    async with serve_plant(plant) as server:
        urls = [
            f"udp://{u.host}:{server.port_of(u)}?timeout=0.5&src=0.1.0&local_port={fins_port}"
            for u in units
        ]
        async with aiofins.connect(urls[0]) as first, aiofins.connect(urls[1]) as second:
            for _ in range(20):
                assert await first.read("D0") == [11]
                assert await second.read("D0") == [12]
            with pytest.raises(CommandError, match="bound by another session"):
                async with aiofins.connect(urls[0].replace("&src=0.1.0", "")):
                    pass  # a second socket to one PLC would share its replies
        async with aiofins.Pool() as pool:
            for _ in range(5):
                for url, value in zip(urls, (11, 12), strict=True):
                    async with pool.client(url) as client:
                        assert await client.read("D0") == [value]
