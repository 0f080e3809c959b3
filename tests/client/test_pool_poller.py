"""Pool and poller against virtual PLCs over loopback UDP/TCP."""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Callable

import anyio
import anyio.lowlevel
import pytest

from aiofins.connection import connect
from aiofins.poller import Poller, PollerState, Quality, ScanState, TagReading, TimerState
from aiofins.pool import Pool
from aiofins.protocol.errors import (
    AddressError,
    CommandError,
    ConnectionLost,
    DecodeError,
    FinsTcpError,
    FinsTimeout,
)
from aiofins.simulator.faults import FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator

from ..session.test_session_tcp import TcpPeer, tcp_server
from ..virtual_time import on_virtual_time

pytestmark = pytest.mark.anyio


async def test_pool_shares_one_session_among_tasks(url: str) -> None:
    async with Pool() as pool:
        seen = set()

        async def user(i: int) -> None:
            async with pool.client(url) as plc:
                seen.add(id(plc.session))
                await plc.write(f"D{i}", [i])
                assert await plc.read(f"D{i}") == [i]

        async with anyio.create_task_group() as tg:
            for i in range(20):
                tg.start_soon(user, i)
        assert len(seen) == 1
        (stats,) = pool.stats(url).values()
        assert stats.sessions == 1
        assert stats.completed == 40
        assert stats.in_use == 0


async def test_extra_udp_sessions_get_their_own_source_node(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(max_per_endpoint=3) as pool:
        sources = set()
        release = anyio.Event()

        async def hold() -> None:
            async with pool.client(url) as plc:
                sources.add(plc.session.source.node)
                assert await plc.read("D0") == [0]
                await release.wait()

        async with anyio.create_task_group() as tg:
            for _ in range(3):
                tg.start_soon(hold)
            while len(sources) < 3:
                await anyio.sleep(0.01)
            release.set()
        assert len(sources) == 3
        assert pool.stats(url)[f"udp://127.0.0.1:{sim.udp_port}"].sessions == 3


async def test_unreachable_endpoint_fails_fast_with_backoff(anyio_backend: object) -> None:
    async with Pool(backoff_min=5.0) as pool:
        for _ in range(2):
            with pytest.raises(ConnectionLost):
                async with pool.client("tcp://127.0.0.1:1") as plc:
                    await plc.read("D0")
        (stats,) = pool.stats("tcp://127.0.0.1:1").values()
        assert stats.connect_failures == 1  # the second call did not try again


@pytest.fixture
async def two_plcs(anyio_backend: object) -> AsyncIterator[tuple[Simulator, Simulator]]:
    slow_plan = FaultPlan(seed=3)
    async with (
        run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as fast,
        run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=slow_plan) as slow,
    ):
        yield fast, slow


async def test_poller_keeps_healthy_plcs_on_schedule_and_marks_quality(
    two_plcs: tuple[Simulator, Simulator],
) -> None:
    fast, slow = two_plcs
    fast_url = f"udp://127.0.0.1:{fast.udp_port}"
    slow_url = f"udp://127.0.0.1:{slow.udp_port}"
    async with Pool(timeout=0.3, retries=0) as pool:
        async with pool.client(fast_url) as plc:
            await plc.write_value("D10", 12.5, "float32")
        async with pool.client(slow_url) as plc:
            await plc.write("D0", [7])
        slow.plan.rule = FaultRule(drop_request=1.0)  # the slow PLC stops answering
        scans: dict[str, list[Quality]] = {"fast": [], "slow": []}
        async with Poller(pool) as poller:
            poller.add_group("fast", fast_url, {"t": "D10:float32"}, interval=0.05)
            poller.add_group("slow", slow_url, {"n": "D0"}, interval=0.05, timeout=0.3)
            with anyio.fail_after(10):
                async for snap in poller:
                    scans[snap.group].append(snap["t" if snap.group == "fast" else "n"].quality)
                    if snap.group == "fast":
                        assert snap["t"].value == 12.5
                    if len(scans["slow"]) >= 2:
                        break
        # While each slow scan waited 0.3 s for a timeout, the fast PLC kept being scanned.
        assert len(scans["fast"]) >= 6
        assert set(scans["fast"]) == {Quality.GOOD}
        assert scans["slow"][:2] == [Quality.ERROR, Quality.ERROR]
        assert poller.groups["slow"].missed >= 1


async def test_scans_of_one_group_at_once_each_borrow_and_give_back(sim: Simulator) -> None:
    """A group keeps its pool lease between scans; scan_once beside another scan of the same
    group (its lease in use) borrows with a lease of its own, and both give the client back."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(max_per_endpoint=2) as pool:
        poller = Poller(pool)
        group = poller.add_group("g", url, {"a": "D0", "b": "D1:int32"}, interval=1)
        async with pool.client(url) as plc:
            await plc.write("D0", [7, 0xFFFF, 0xFFFF])
        snaps = []

        async def scan() -> None:
            snaps.append(await poller.scan_once(group))

        for _ in range(2):
            async with anyio.create_task_group() as tg:
                for _ in range(3):
                    tg.start_soon(scan)
        assert [s.values if s else None for s in snaps] == [{"a": 7, "b": -1}] * 6
        (stats,) = pool.stats(url).values()
        assert stats.in_use == 0 and stats.completed == 7
        assert group.scans == 6 and group._lease is not None


@on_virtual_time
async def test_poller_stale_quality_and_changes_only() -> None:
    """On virtual time (asyncio, trio; uvloop's clock cannot be virtual): the short timeout
    ends only the scans of the outage, never a loaded machine's slow answer."""
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as sim:
        await _test_poller_stale_quality_and_changes_only(sim)


async def _test_poller_stale_quality_and_changes_only(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=0.2, retries=0) as pool:
        poller = Poller(pool, changes_only=True)
        group = poller.add_group("g", url, {"a": "D0", "b": "D1"}, interval=1)
        first = await poller.scan_once(group)
        assert first is not None and first.changed == {"a", "b"}
        assert await poller.scan_once(group) is None  # nothing changed
        async with pool.client(url) as plc:
            await plc.write("D1", [5])
        third = await poller.scan_once(group)
        assert third is not None and set(third.readings) == {"b"}
        assert third["b"].value == 5
        sim.plan.rule = FaultRule(drop_request=1.0)
        fourth = await poller.scan_once(group)
        assert fourth is not None
        assert fourth["a"].quality is Quality.STALE and fourth["a"].value == 0
        assert fourth.error is not None and "FinsTimeout" in fourth.error
        sim.plan.rule = FaultRule()
        fifth = await poller.scan_once(group)  # good again: same values, quality changed
        assert fifth is not None and fifth.changed == {"a", "b"}
        assert (fifth["a"].value, fifth["b"].value) == (0, 5)
        assert {r.quality for r in fifth.readings.values()} == {Quality.GOOD}
        assert await poller.scan_once(group) is None
        (stats,) = pool.stats(url).values()
        assert stats.in_use == 0  # every scan, good or failed, gave its client back
        assert (group.scans, group.errors) == (6, 1)


async def _until(condition: Callable[[], bool]) -> None:
    with anyio.fail_after(5):
        while not condition():
            await anyio.sleep(0.01)


@on_virtual_time
async def test_pool_health_checks_and_closes_idle_sessions() -> None:
    """On virtual time (asyncio, trio; uvloop's clock cannot be virtual): the 0.1 s health
    check fails only when the PLC is silent, never on a loaded machine's slow answer."""
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as sim:
        await _test_pool_health_checks_and_closes_idle_sessions(sim)


async def _test_pool_health_checks_and_closes_idle_sessions(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(health_interval=0.05, idle_timeout=60, timeout=0.1, retries=0) as pool:
        async with pool.client(url) as plc:
            assert await plc.read("D0") == [0]
        before = sim.plc.commands[0x0601] if isinstance(sim.plc, VirtualPLC) else 0
        await _until(
            lambda: isinstance(sim.plc, VirtualPLC) and sim.plc.commands[0x0601] > before
        )  # 0601 health check sent
        sim.plan.rule = FaultRule(drop_request=1.0)  # the PLC goes silent
        await _until(lambda: pool.stats(url)[f"udp://127.0.0.1:{sim.udp_port}"].sessions == 0)
        assert pool.stats(url)[f"udp://127.0.0.1:{sim.udp_port}"].health_failures == 1
        sim.plan.rule = FaultRule()
        async with pool.client(url) as plc:  # a new session is opened on demand
            assert await plc.read("D0") == [0]
    async with Pool(idle_timeout=0.05, health_interval=60) as pool:
        async with pool.client(url) as plc:
            await plc.read("D0")
        await _until(lambda: pool.stats(url)[f"udp://127.0.0.1:{sim.udp_port}"].sessions == 0)


async def test_pool_counts_lost_connections_and_failed_reconnects(anyio_backend: object) -> None:
    """A session's own reconnect failures count with the pool's, and the counters of a
    session the pool closes stay counted (they only grow)."""
    async with Pool(timeout=0.5, retries=0, idle_timeout=60, health_interval=60) as pool:
        async with run_simulator(VirtualPLC(), tcp=("127.0.0.1", 0)) as sim:
            url = f"tcp://127.0.0.1:{sim.tcp_port}"
            async with pool.client(url) as plc:
                assert await plc.read("D0") == [0]
        # The virtual PLC is gone: its server closed the connection.
        await _until(lambda: pool.stats(url)[url].disconnects == 1)
        with pytest.raises(ConnectionLost):
            async with pool.client(url) as plc:
                await plc.read("D0")  # the session tries to reconnect, and fails
        stats = pool.stats(url)[url]
        assert (stats.sessions, stats.connects, stats.completed) == (1, 1, 1)
        assert (stats.disconnects, stats.connect_failures) == (1, 1)
        await pool.aclose()  # the session closes; its counters stay with the endpoint
        stats = pool.stats(url)[url]
        assert stats.sessions == 0 and stats.in_flight == 0
        assert (stats.connects, stats.completed, stats.disconnects, stats.connect_failures) == (
            1,
            1,
            1,
            1,
        )


def test_unknown_options_are_refused_when_the_pool_is_made() -> None:
    """Not at the first borrow, where a poller would only show them as a scan error."""
    with pytest.raises(CommandError, match=r"unknown option\(s\): connect_options \(known: "):
        Pool(connect_options={"timeout": 1})
    Pool(timeout=0.5, retries=0, baudrate=115200, tcp_node=5, tcp_gather_writes=False)


async def test_connect_names_its_options_when_refusing_one() -> None:
    with pytest.raises(CommandError, match=r"unknown option\(s\): foo \(known: .*timeout"):
        async with connect("udp://127.0.0.1:9", foo=1):
            pass


def test_add_group_checks_its_url_tags_and_timing_at_once() -> None:
    poller = Poller(Pool())
    with pytest.raises(AddressError, match="unknown area 'Q'"):
        poller.add_group("g", "udp://127.0.0.1", {"x": "Q0"})
    with pytest.raises(CommandError, match="unknown scheme"):
        poller.add_group("g", "http://127.0.0.1", {"x": "D0"})
    with pytest.raises(CommandError, match="timeout must be a positive"):
        poller.add_group("g", "udp://127.0.0.1", {"x": "D0"}, timeout=0)
    with pytest.raises(AddressError, match="run past the end"):
        poller.add_group("g", "udp://127.0.0.1", {"x": "D32767:float32"})
    assert poller.groups == {}
    poller.add_group("g", "udp://127.0.0.1", {"x": "D0:float32"})
    assert list(poller.groups) == ["g"]


async def test_closing_the_pool_abandons_a_connect_in_progress(anyio_backend: object) -> None:
    """A FINS/TCP peer that accepts but never answers the handshake: closing the pool does not
    wait out the connect timeout, and the waiting borrower gets ConnectionLost."""
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    url = f"tcp://127.0.0.1:{port}"
    outcome: list[BaseException] = []

    async def borrow(pool: Pool) -> None:
        try:
            async with pool.client(url):
                pass
        except Exception as exc:  # what the borrower gets (an AssertionError, it was)
            outcome.append(exc)

    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(listener.serve, lambda stream: anyio.sleep_forever())
        with anyio.fail_after(3):  # the connect timeout is 5 s
            async with Pool() as pool:
                tg.start_soon(borrow, pool)
                await anyio.wait_all_tasks_blocked()
            with pytest.raises(ConnectionLost, match="the pool is closed"):
                async with pool.client(url):
                    pass
            while not outcome:
                await anyio.sleep(0.01)
        tg.cancel_scope.cancel()
    assert len(outcome) == 1 and isinstance(outcome[0], ConnectionLost), outcome
    assert "the pool closed while connecting" in str(outcome[0])


async def test_a_group_without_a_time_limit_still_scans(sim: Simulator) -> None:
    """``timeout=math.inf`` is a valid group timeout (the poller and the session accept it);
    the pool refused it when the poller started to pass it on, and every scan failed with
    CommandError."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool() as pool:
        poller = Poller(pool)
        group = poller.add_group("g", url, {"a": "D0"}, timeout=math.inf)
        scan = await poller.scan_once(group)
        assert scan is not None and scan.error is None
        assert scan["a"].quality is Quality.GOOD
        async with pool.client(url, timeout=math.inf) as plc:
            assert await plc.read("D0", timeout=math.inf) == [0]
        for bad in (0.0, -1.0, math.nan):
            with pytest.raises(CommandError):
                pool.client(url, timeout=bad)


def _traceback_length(exc: BaseException) -> int:
    n, tb = 0, exc.__traceback__
    while tb is not None:
        n, tb = n + 1, tb.tb_next
    return n


async def test_borrowers_sharing_a_failed_connect_get_its_traceback_once(
    anyio_backend: object,
) -> None:
    """Every borrower waiting for a connect gets its one error object: re-raising it as is
    made its traceback grow by each earlier borrower's frames (here 20 borrowers)."""
    peer = TcpPeer(refuse=0x20, handshake_gate=anyio.Event())  # "all connections in use"
    async with tcp_server(peer):
        url = f"tcp://127.0.0.1:{peer.port}"
        errors: list[BaseException] = []
        lengths: set[int] = set()

        async def borrow() -> None:
            try:
                async with pool.client(url):
                    pass
            except FinsTcpError as exc:
                errors.append(exc)
                lengths.add(_traceback_length(exc))  # as each borrower sees it

        async with Pool(timeout=5) as pool:
            with anyio.fail_after(5):
                async with anyio.create_task_group() as tg:
                    for _ in range(20):
                        tg.start_soon(borrow)
                    await anyio.wait_all_tasks_blocked()
                    assert peer.handshake_gate is not None
                    peer.handshake_gate.set()
        assert len(errors) == 20
        assert len(lengths) == 1, sorted(lengths)


@on_virtual_time
async def test_a_borrower_waits_for_a_connection_at_most_its_timeout() -> None:
    """A FINS/TCP peer that answers the handshake late: borrowers (and poller scans) gave up
    only after the connect timeout (5 s) whatever their timeout. Now each waits at most its
    own, and the attempt goes on for the next borrower. On virtual time (asyncio, trio;
    uvloop's clock cannot be virtual): each wait is asserted exactly."""
    peer = TcpPeer(handshake_gate=anyio.Event())
    async with tcp_server(peer):
        url = f"tcp://127.0.0.1:{peer.port}"
        still = "no connection within {} s: a connection attempt is still in progress"
        async with Pool(timeout=0.3) as pool:
            start = anyio.current_time()
            with pytest.raises(FinsTimeout, match=still.format(0.3)):
                async with pool.client(url):  # the pool's timeout by default
                    pass
            assert anyio.current_time() - start == pytest.approx(0.3, abs=1e-6)
            start = anyio.current_time()
            with pytest.raises(FinsTimeout, match=still.format(0.2)):
                async with pool.client(url, timeout=0.2):
                    pass
            assert anyio.current_time() - start == pytest.approx(0.2, abs=1e-6)
            with anyio.move_on_after(0.1):  # a borrower cancelled by its own deadline
                async with pool.client(url, timeout=10):
                    pass
            poller = Poller(pool)
            group = poller.add_group("g", url, {"a": "D0"}, timeout=0.25)
            start = anyio.current_time()
            scan = await poller.scan_once(group)
            assert anyio.current_time() - start == pytest.approx(0.25, abs=1e-6)
            assert scan is not None and scan["a"].quality is Quality.ERROR
            assert scan.error is not None and scan.error.startswith("FinsTimeout")
            assert peer.handshake_gate is not None
            peer.handshake_gate.set()  # the PLC answers at last
            async with pool.client(url) as plc:
                assert await plc.read("D0") == [0x1000]
            assert peer.connections == 1  # the borrowers' giving up did not end the attempt
            stats = pool.stats(url)[url]
            assert stats.connect_failures == 0
            assert stats.in_use == 0  # no borrower that gave up still counts as a user


async def test_a_poller_outliving_its_pool_marks_scans_as_errors(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=0.5) as pool:
        poller = Poller(pool)
        group = poller.add_group("g", url, {"a": "D0"}, interval=1)
        first = await poller.scan_once(group)
        assert first is not None and first["a"].quality is Quality.GOOD
    after = await poller.scan_once(group)  # the pool is closed: an error scan, not a crash
    assert after is not None and after["a"].quality is Quality.STALE
    assert after.error == "ConnectionLost: the pool is closed"


async def test_a_tag_holding_no_value_of_its_type_fails_alone(sim: Simulator) -> None:
    """Invalid BCD in one tag failed every tag of the scan (and read_tags for all)."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    assert isinstance(sim.plc, VirtualPLC)
    sim.plc.write("D0", [42])
    sim.plc.write("D10", [0x1234])
    tags = {"speed": "D0", "preset": "D10:bcd16", "name": "D20:string:2"}
    async with Pool(timeout=0.5) as pool:
        async with pool.client(url) as plc:
            assert await plc.read_tags(tags) == {"speed": 42, "preset": 1234, "name": ""}
            sim.plc.write("D10", [0x12AB])
            with pytest.raises(DecodeError, match=r"tag 'preset' \(D10:bcd16\): 12AB is not"):
                await plc.read_tags(tags)
            errors: dict[str, str] = {}
            assert await plc.read_tags(tags, errors=errors) == {"speed": 42, "name": ""}
            assert list(errors) == ["preset"]
        poller = Poller(pool)
        group = poller.add_group("g", url, tags, interval=1)
        sim.plc.write("D10", [0x0042])
        first = await poller.scan_once(group)
        assert first is not None and first["preset"].value == 42
        sim.plc.write("D10", [0x12AB])
        sim.plc.write("D20", [0xFF41])  # not ASCII
        snap = await poller.scan_once(group)
        assert snap is not None and snap.error is None
        assert snap["speed"].quality is Quality.GOOD and snap["speed"].value == 42
        assert snap["preset"].quality is Quality.STALE and snap["preset"].value == 42
        assert (
            snap["preset"].error is not None and "tag 'preset' (D10:bcd16)" in snap["preset"].error
        )
        assert snap["name"].quality is Quality.STALE and "tag 'name'" in str(snap["name"].error)
        assert snap.changed == {"preset", "name"}


async def test_poller_groups_run_on_one_timer_with_states(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=1) as pool:
        async with pool.client(url) as plc:
            await plc.write("D0", [1, 2])
        poller = Poller(pool)
        fast = poller.add_group("fast", url, {"a": "D0", "b": "D1"}, interval=0.02)
        slow = poller.add_group("slow", url, {"a": "D0"}, interval=10)
        assert (fast.state, slow.state) == (ScanState.STOPPED, ScanState.STOPPED)
        seen: dict[str, int] = {"fast": 0, "slow": 0}
        async with poller:
            assert fast.state is ScanState.IDLE  # started, its first scan due now
            with anyio.fail_after(5):
                async for snap in poller:
                    seen[snap.group] += 1
                    if snap.group == "fast":
                        assert dict(snap.readings) == {
                            "a": TagReading(1, Quality.GOOD, snap.timestamp),
                            "b": TagReading(2, Quality.GOOD, snap.timestamp),
                        }
                        assert snap.values == {"a": 1, "b": 2} and len(snap.readings) == 2
                        assert snap.changed == ({"a", "b"} if seen["fast"] == 1 else set())
                    if seen["fast"] == 5:
                        break
            assert seen == {"fast": 5, "slow": 1}  # the slow group waits its 10 s
            assert slow.state is ScanState.IDLE
            # One schedule entry per group; the next slow scan ~10 s after its first.
            assert sorted(g.name for _, _, g in poller._schedule) == ["fast", "slow"]
        assert (fast.state, slow.state) == (ScanState.STOPPED, ScanState.STOPPED)


def state_of(poller: Poller) -> PollerState:
    return poller.state  # (read anew each time: mypy would narrow the attribute)


async def test_a_poller_runs_once_and_says_where_it_is() -> None:
    async with Pool() as pool:
        poller = Poller(pool)
        assert state_of(poller) is PollerState.NEW
        async with poller:
            assert state_of(poller) is PollerState.RUNNING
            with pytest.raises(RuntimeError, match="the poller is running"):
                await poller.__aenter__()
        assert state_of(poller) is PollerState.CLOSED
        with pytest.raises(RuntimeError, match="a poller runs once, make a new one"):
            async with poller:
                pass
        assert state_of(poller) is PollerState.CLOSED


def timer_of(poller: Poller) -> tuple[TimerState, float]:
    return poller._timer_state, poller._timer_at


async def test_the_timer_is_idle_without_groups_and_armed_for_the_next_scan_time(
    sim: Simulator,
) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool() as pool, Poller(pool) as poller:
        await anyio.lowlevel.checkpoint()  # (the timer's task starts)
        assert timer_of(poller) == (TimerState.IDLE, math.inf)
        group = poller.add_group("g", url, {"a": "D0"}, interval=60.0)
        async for snap in poller:
            assert snap.scan == 1
            break
        state, at = timer_of(poller)
        assert state is TimerState.ARMED
        assert 59.0 < at - anyio.current_time() <= 60.0  # the next scan time, a minute on
        assert group.state is ScanState.IDLE
    assert timer_of(poller) == (TimerState.IDLE, math.inf)
