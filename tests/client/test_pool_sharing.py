"""Which borrowers of a Pool share a session: those that address the same PLC the same way.

The peer is a small FINS network behind one Ethernet unit, served by the simulator's UDP and
FINS/TCP servers: the gateway PLC (0.1.0), a PLC on the same network (0.7.0) and one on a
network behind it (3.5.0), each with its own memory.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable

import anyio
import pytest

from aiofins.client import Client
from aiofins.connection import connect
from aiofins.poller import Poller, Quality
from aiofins.pool import Pool
from aiofins.protocol.errors import CommandError, DecodeError
from aiofins.protocol.header import CommandFrame, FinsAddress
from aiofins.session.nodes import SOURCE_NODES
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator

from ..virtual_time import on_virtual_time

pytestmark = pytest.mark.anyio


class Site:
    """PLCs behind one Ethernet unit: a frame goes to the PLC its DNA/DA1 names (DNA 0 and
    DA1 0 mean the gateway's network and the gateway); an unknown address goes to the
    gateway, which answers a relay error or drops it as a PLC does."""

    def __init__(self, gateway: VirtualPLC, *others: VirtualPLC) -> None:
        self.gateway = gateway
        self.plcs = {(p.address.network, p.address.node): p for p in (gateway, *others)}
        self.address = gateway.address

    def handle_frame(self, frame: bytes, *, from_network: bool = True) -> bytes | None:
        try:
            dest = CommandFrame.decode(frame).header.destination
        except DecodeError:
            return None
        network = dest.network or self.gateway.address.network
        node = dest.node or self.gateway.address.node
        plc = self.plcs.get((network, node), self.gateway)
        return plc.handle_frame(frame, from_network=from_network)


def _plc(network: int, node: int, d0: int) -> VirtualPLC:
    plc = VirtualPLC(network=network, node=node)
    plc.write("D0", [d0])
    return plc


@pytest.fixture
async def site(anyio_backend: object) -> AsyncIterator[Simulator]:
    plcs = Site(_plc(0, 1, 100), _plc(0, 7, 700), _plc(3, 5, 350))
    async with run_simulator(plcs, udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0)) as sim:
        yield sim


def _base(sim: Simulator, scheme: str) -> str:
    return f"{scheme}://127.0.0.1:{sim.udp_port if scheme == 'udp' else sim.tcp_port}"


#: (query, D0 of the PLC it addresses, request timeout)
BORROWERS = [
    ("?node=1", 100, 2.0),
    ("?node=7&timeout=1.5", 700, 1.5),
    ("?dest=3.5.0", 350, 2.0),
    ("?node=7", 700, 2.0),
    ("", 100, 2.0),  # 127.0.0.1: node 1, the gateway
]


async def _what_it_gives(plc: Client) -> tuple[FinsAddress, float, list[int]]:
    return plc.session.dest, plc.session.timeout, await plc.read("D0")


@pytest.mark.parametrize("scheme", ["udp", "tcp"])
async def test_each_borrower_gets_what_connect_with_its_url_gives(
    site: Simulator, scheme: str
) -> None:
    """Node 1's session was lent to every URL of the host:port: node 7's and 3.5.0's
    borrowers read the gateway's D0, with its timeout."""
    base = _base(site, scheme)
    alone = {}
    for query, d0, timeout in BORROWERS:
        async with connect(base + query) as plc:
            alone[query] = await _what_it_gives(plc)
            assert alone[query][1:] == (timeout, [d0])
    async with Pool() as pool:
        for _ in range(2):  # lent again: the same session per key
            async with anyio.create_task_group() as tg:
                for query, _, _ in BORROWERS:

                    async def borrow(query: str = query) -> None:
                        async with pool.client(base + query) as plc:
                            assert await _what_it_gives(plc) == alone[query], query

                    tg.start_soon(borrow)
        keys = {key for query, _, _ in BORROWERS for key in pool.stats(base + query)}
        assert keys == {
            f"{base}?node=1",
            f"{base}?node=7&timeout=1.5",
            f"{base}?dest=3.5.0",
            f"{base}?node=7",
            base,
        }
        for query, _, _ in BORROWERS:
            (stats,) = pool.stats(base + query).values()
            assert (stats.sessions, stats.completed) == (1, 2)
        # One spelling per key: the same options in another order or form share the session.
        async with pool.client(f"{base}?timeout=1.50&node=07") as plc:
            assert await _what_it_gives(plc) == alone["?node=7&timeout=1.5"]
        assert pool.stats(f"{base}?node=7&timeout=1.5")[f"{base}?node=7&timeout=1.5"].sessions == 1


async def test_udp_sessions_to_one_host_port_have_their_own_source_nodes(site: Simulator) -> None:
    """An Ethernet unit replies to the last port it saw for a source node: each UDP session
    to the gateway, whatever PLC it addresses, needs a source node of its own, and none may
    be the node of a PLC addressed there."""
    base = _base(site, "udp")
    async with Pool() as pool:
        sources = []
        dests = []
        for query, d0, _ in BORROWERS:
            async with pool.client(base + query) as plc:
                assert await plc.read("D0") == [d0]
                sources.append(plc.session.source)
                dests.append(plc.session.dest.node)
        assert len({s.node for s in sources}) == len(BORROWERS)
        assert not {s.node for s in sources} & set(dests)
        # A source node named in the URL is kept; one in use on the link is refused.
        async with pool.client(f"{base}?node=7&src=0.200.0") as plc:
            assert plc.session.source == FinsAddress(0, 200, 0)
            assert await plc.read("D0") == [700]
        with pytest.raises(CommandError, match="source node 200 is used by another session"):
            async with pool.client(f"{base}?dest=3.5.0&src=0.200.0"):
                pass


async def test_a_pool_session_avoids_source_nodes_held_outside_the_pool(site: Simulator) -> None:
    """Nodes held in the process's registry (by another session's extra SID spaces, or a
    session of another pool) are not given to a pool's sessions, and a pool's sessions hold
    theirs there while they live."""
    base = _base(site, "udp")
    link = f"udp://127.0.0.1:{site.udp_port}"
    SOURCE_NODES.hold(link, 254)  # what connect() would give (127.0.0.1: node 254)
    try:
        async with Pool() as pool:
            async with pool.client(base) as plc:
                assert await plc.read("D0") == [100]
                assert plc.session.source.node == 253
                assert SOURCE_NODES.in_use(link) == {253, 254}
            with pytest.raises(CommandError, match=r"source node 254 is used .* or process"):
                async with pool.client(f"{base}?src=0.254.0&node=7"):
                    pass
        assert SOURCE_NODES.in_use(link) == {254}
    finally:
        SOURCE_NODES.release(link, 254)
    assert SOURCE_NODES.in_use(link) == frozenset()


@pytest.mark.parametrize("scheme", ["udp", "tcp"])
async def test_poller_groups_for_a_gateway_and_the_plcs_behind_it(
    site: Simulator, scheme: str
) -> None:
    """Two groups for the gateway PLC and a PLC behind it both reported the gateway's D0."""
    base = _base(site, scheme)
    async with Pool() as pool:
        poller = Poller(pool)
        groups = {
            query: poller.add_group(query or "plain", base + query, {"d0": "D0"}, interval=1)
            for query, _, _ in BORROWERS
        }
        for _ in range(2):
            for query, d0, _ in BORROWERS:
                scan = await poller.scan_once(groups[query])
                assert scan is not None and scan.error is None
                assert (scan["d0"].quality, scan["d0"].value) == (Quality.GOOD, d0), query


async def _serve_like_an_ethernet_unit(
    site: Site,
    ready: Callable[[int], None],
    host: str = "127.0.0.1",
    *,
    task_status: anyio.abc.TaskStatus[None],
) -> None:
    """FINS/UDP as an Ethernet unit does it: a reply, ready a few milliseconds later (the
    CPU's turn), goes to the last UDP port that a command came from *for its source node*
    (SA1), not to the port of the command."""
    async with (
        await anyio.create_udp_socket(local_host=host) as sock,
        anyio.create_task_group() as tg,
    ):
        ready(sock.extra(anyio.abc.SocketAttribute.local_port))
        task_status.started()
        last_port: dict[int, tuple[str, int]] = {}
        sending = anyio.Lock()

        async def answer(source: int, reply: bytes) -> None:
            await anyio.sleep(0.003)
            async with sending:
                await sock.sendto(reply, *last_port[source])

        async for frame, peer in sock:
            try:
                source = CommandFrame.decode(frame).header.source.node
            except DecodeError:
                continue
            last_port[source] = peer
            reply = site.handle_frame(frame)
            if reply is not None:
                tg.start_soon(answer, source, reply)


@on_virtual_time
async def test_sessions_to_one_ethernet_unit_do_not_steal_each_others_replies() -> None:
    """Each key has its own session (socket): were their source nodes the same, the unit
    would send one session's replies to the other's socket. On virtual time (asyncio, trio;
    uvloop's clock cannot be virtual): no timeout is a loaded machine's."""
    plcs = Site(_plc(0, 1, 100), _plc(0, 7, 700), _plc(3, 5, 350))
    ports: list[int] = []
    async with anyio.create_task_group() as tg:
        await tg.start(_serve_like_an_ethernet_unit, plcs, ports.append)
        base = f"udp://127.0.0.1:{ports[0]}"
        async with Pool(timeout=2.0, retries=0) as pool:

            async def reads(query: str, d0: int) -> None:
                for _ in range(50):
                    async with pool.client(base + query) as plc:
                        assert await plc.read("D0") == [d0], query

            with anyio.fail_after(10):
                async with anyio.create_task_group() as readers:
                    for query, d0, _ in BORROWERS:
                        readers.start_soon(reads, query, d0)
            assert all(s.timeouts == 0 for s in pool.stats().values())
        tg.cancel_scope.cancel()


@pytest.mark.parametrize(
    ("host", "spellings"),
    [
        ("127.0.0.1", ["127.0.0.1", "localhost"]),
        ("::1", ["[::1]", "[0:0:0:0:0:0:0:1]", "[0::1]"]),
    ],
    ids=["name-and-address", "ipv6-spellings"],
)
async def test_one_ethernet_unit_under_several_names_gets_a_source_node_per_session(
    anyio_backend: object, host: str, spellings: list[str]
) -> None:
    """Sessions to one unit were told apart by the host as written: ``localhost`` and
    ``127.0.0.1`` (or two spellings of an IPv6 address) got the same source node, and the
    unit sent one session's replies to the other's socket. (On the loop's real clock: a
    name is resolved in a worker thread, which virtual time would jump past; each call has
    1.3 s or more for a few milliseconds' work.)"""
    plcs = Site(_plc(0, 1, 100), _plc(0, 7, 700), _plc(3, 5, 350))
    ports: list[int] = []
    async with anyio.create_task_group() as tg:
        await tg.start(_serve_like_an_ethernet_unit, plcs, ports.append, host)
        urls = [f"udp://{name}:{ports[0]}?timeout=1.{i + 3}" for i, name in enumerate(spellings)]
        async with Pool(retries=0) as pool:
            sources = set()
            for url in urls:
                async with pool.client(url) as plc:
                    sources.add(plc.session.source.node)
            assert len(sources) == len(urls)

            async def reads(url: str) -> None:
                for _ in range(30):
                    async with pool.client(url) as plc:
                        assert await plc.read("D0") == [100], url

            with anyio.fail_after(10):
                async with anyio.create_task_group() as readers:
                    for url in urls:
                        readers.start_soon(reads, url)
            stats = pool.stats().values()
            assert all(s.timeouts == s.late_replies == 0 for s in stats)
            # A source node named in the URL is refused under another name of the unit too.
            async with pool.client(f"{urls[0]}&src=0.200.0"):
                with pytest.raises(CommandError, match="source node 200 is used"):
                    async with pool.client(f"{urls[1]}&src=0.200.0"):
                        pass
        tg.cancel_scope.cancel()


async def test_a_fixed_tcp_node_is_refused_for_a_second_session_to_the_plc(
    site: Simulator,
) -> None:
    """With ``Pool(tcp_node=5)`` every key to a FINS/TCP PLC asked for node 5: all but the
    first handshake were refused by the PLC (0x21), and the key backed off."""
    base = _base(site, "tcp")
    async with Pool(tcp_node=5, timeout=1) as pool:
        async with pool.client(base + "?node=1") as plc:
            assert plc.session.source.node == 5
            for other in (base + "?node=7", base.replace("127.0.0.1", "localhost")):
                with pytest.raises(CommandError, match=r"node 5 \(tcp_node\) is held by an"):
                    async with pool.client(other):
                        pass
            assert await plc.read("D0") == [100]
        assert pool.stats(base + "?node=7")[base + "?node=7"].connect_failures == 0
    async with Pool(tcp_node=5, max_per_endpoint=3, timeout=1) as pool:
        async with anyio.create_task_group() as tg:  # busy: shared, no second connection
            for _ in range(6):

                async def borrow() -> None:
                    async with pool.client(base) as plc:
                        assert await plc.read("D0") == [100]

                tg.start_soon(borrow)
        assert pool.stats(base)[base].sessions == 1
    async with (  # without it the PLC assigns each its node
        Pool(timeout=1) as pool,
        pool.client(base + "?node=1") as a,
        pool.client(base + "?node=7") as b,
    ):
        assert (await a.read("D0"), await b.read("D0")) == ([100], [700])


@pytest.mark.parametrize("scheme", ["udp", "tcp"])
async def test_connect_keywords_win_over_the_url_and_the_url_over_a_pools(
    site: Simulator, scheme: str
) -> None:
    """connect(): a keyword given wins over the same option in the URL (timeout as dest); a
    Pool's keyword options are defaults for every endpoint: the URL's own option wins."""
    base = _base(site, scheme)
    async with connect(base + "?node=7&timeout=0.3", timeout=1.5, dest="3.5.0") as plc:
        assert await _what_it_gives(plc) == (FinsAddress(3, 5, 0), 1.5, [350])
    async with connect(base + "?node=7&timeout=0.3") as plc:
        assert await _what_it_gives(plc) == (FinsAddress(0, 7, 0), 0.3, [700])
    async with connect(base, timeout=1.5) as plc:
        assert (await _what_it_gives(plc))[1:] == (1.5, [100])
    async with Pool(timeout=1.5, dest="3.5.0") as pool:
        async with pool.client(base + "?node=7&timeout=0.3") as plc:
            assert await _what_it_gives(plc) == (FinsAddress(0, 7, 0), 0.3, [700])
        async with pool.client(base + "?dest=0.1.0") as plc:
            assert await _what_it_gives(plc) == (FinsAddress(0, 1, 0), 1.5, [100])
        async with pool.client(base) as plc:
            assert await _what_it_gives(plc) == (FinsAddress(3, 5, 0), 1.5, [350])


async def test_plain_connect_sessions_to_one_unit_get_their_own_source_nodes(
    anyio_backend: object,
) -> None:
    """Two ``connect()`` sessions to one Ethernet unit (two workers' clients, a script and a
    poller) both took the default source node: the unit sent each one's replies to the
    other's socket, where a read with the same SID got the other's words."""
    gateway = _plc(0, 1, 0)
    gateway.write("D0", list(range(100, 110)))
    ports: list[int] = []
    async with anyio.create_task_group() as tg:
        await tg.start(_serve_like_an_ethernet_unit, Site(gateway), ports.append)
        url = f"udp://127.0.0.1:{ports[0]}"
        link = f"udp://127.0.0.1:{ports[0]}"
        async with connect(url, retries=0) as a, connect(url, retries=0) as b:
            assert a.session.source.node == 254  # the first keeps the default
            assert b.session.source.node == 253
            assert SOURCE_NODES.in_use(link) == {253, 254}
            got: dict[int, list[int]] = {0: [], 1: []}

            async def reads(plc: Client, word: int) -> None:
                for _ in range(60):
                    got[word] += await plc.read(f"D{word}")

            with anyio.fail_after(10):
                async with anyio.create_task_group() as readers:
                    readers.start_soon(reads, a, 0)
                    readers.start_soon(reads, b, 1)
            assert got == {0: [100] * 60, 1: [101] * 60}
            for plc in (a, b):
                stats = plc.session.stats
                assert (stats.completed, stats.timeouts, stats.unsolicited) == (60, 0, 0)
            # A source node named in use on the link is refused, as a pool refuses it.
            with pytest.raises(CommandError, match=r"source node 254 is used .* or process"):
                async with connect(url, src="0.254.0"):
                    pass
            with pytest.raises(CommandError, match=r"source node 253 is used"):
                async with connect(f"udp://localhost:{ports[0]}?src=0.253.0"):
                    pass
            async with connect(url + "?src=0.200.0") as c:
                assert c.session.source.node == 200
                assert await c.read("D2") == [102]
        assert SOURCE_NODES.in_use(link) == frozenset()  # given back on closing
        tg.cancel_scope.cancel()
