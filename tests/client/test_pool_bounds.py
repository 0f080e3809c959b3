"""A Pool's bounds and boundaries: arguments, sessions held, health checks, backoff, errors.

Peers are loopback: the simulator, FINS/TCP peers that misbehave on purpose, UDP sockets that
never answer, and loopback addresses (127.x.y.z) where nothing listens.
"""

from __future__ import annotations

import logging
import math
import os
import socket
import time
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import contextmanager
from typing import Any

import anyio
import pytest

import aiofins
from aiofins.endpoint import parse_endpoint
from aiofins.pool import EntryState, Pool, PoolFull, _Entry
from aiofins.protocol.errors import (
    CommandError,
    ConnectionLost,
    FinsError,
    FinsTimeout,
    FrameError,
)
from aiofins.session.response import SESSION_COUNTERS
from aiofins.simulator.faults import FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator
from tests.conftest import PTY_8N1

from ..session.test_session_tcp import TcpPeer, tcp_server
from ..virtual_time import VIRTUAL_BACKENDS, run_on_virtual_time

pytestmark = pytest.mark.anyio


async def _until(condition: Callable[[], bool], within: float = 5) -> None:
    with anyio.fail_after(within):
        while not condition():
            await anyio.sleep(0.01)


@contextmanager
def _silent_udp() -> Iterator[str]:
    """A UDP socket that takes every datagram and never answers: a dead PLC's URL."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        yield f"udp://127.0.0.1:{silent.getsockname()[1]}"


def _open_descriptors() -> int:
    return len(os.listdir("/proc/self/fd"))


# -- arguments ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"idle_timeout": -1}, "idle_timeout must be a positive number of seconds; got -1"),
        ({"idle_timeout": math.inf}, "idle_timeout must be a positive number"),
        ({"health_interval": math.nan}, "health_interval must be a positive number"),
        ({"health_interval": 0}, "health_interval must be a positive number of seconds"),
        ({"backoff_min": 5, "backoff_max": 1}, r"backoff_min \(5\) must not be above backoff_max"),
        ({"backoff_min": -0.5}, "backoff_min must be a number of seconds, 0 or more"),
        ({"backoff_max": math.inf}, "backoff_max must be a number of seconds"),
        ({"max_sessions": 0}, "max_sessions must be a whole number, at least 1"),
        ({"max_per_endpoint": 1.5}, "max_per_endpoint must be a whole number"),
        ({"idle_timeout": "300"}, "idle_timeout must be a positive number"),
        ({"timeout": math.nan}, "timeout must be a positive number of seconds"),
        ({"tcp_connect_timeout": -1}, "tcp_connect_timeout must be a positive number"),
        ({"dest": "x"}, "FINS address 'x' is not NET.NODE"),
        ({"src": 7}, "a FINS address is a FinsAddress or 'NET.NODE.UNIT' text, got 7"),
        ({"dest": "0.300.0"}, "node address 300 out of range"),
    ],
)
def test_pool_arguments_are_checked_when_the_pool_is_made(
    kwargs: dict[str, Any], message: str
) -> None:
    """They crashed the maintenance task later (idle_timeout=-1, health_interval=nan) or were
    taken as they were (backoff_min above backoff_max)."""
    with pytest.raises(CommandError, match=message):
        Pool(**kwargs)


async def test_a_short_health_interval_does_not_spin(anyio_backend: object) -> None:
    """health_interval=0 spun a core, with no endpoint at all; the shortest accepted one
    is paced (the maintenance sleeps until a session opens, then at least 10 ms a pass)."""
    async with Pool(health_interval=1e-9, idle_timeout=1e-9):
        cpu = time.process_time()
        await anyio.sleep(0.3)
        assert time.process_time() - cpu < 0.1


# -- the body's own exception ------------------------------------------------------------


async def test_an_error_of_the_pool_body_comes_out_as_it_is(sim: Simulator) -> None:
    """It came out wrapped in an ExceptionGroup: ``except aiofins.FinsError`` missed it."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    error = aiofins.FinsTimeout("the application's own")
    with pytest.raises(aiofins.FinsError) as caught:
        async with Pool() as pool:
            async with pool.client(url) as plc:
                assert await plc.read("D0") == [0]
            raise error
    assert caught.value is error
    with pytest.raises(KeyError):
        async with Pool():
            raise KeyError("not a FINS error either")


# -- boundaries ----------------------------------------------------------------------------


async def test_a_peer_assigning_node_300_fails_its_endpoint_alone(
    sim: Simulator, caplog: pytest.LogCaptureFixture
) -> None:
    """A FINS/TCP handshake assigning node 300 raised out of the connect into the pool's
    task group: it cancelled the pool, every other session and the application's task."""
    good = f"udp://127.0.0.1:{sim.udp_port}"
    peer = TcpPeer(assign_node=300)
    reads = 0
    async with tcp_server(peer), Pool(timeout=1) as pool:
        bad = f"tcp://127.0.0.1:{peer.port}"

        async def sibling() -> None:  # the application's other task, on another PLC
            nonlocal reads
            while True:
                async with pool.client(good) as plc:
                    assert await plc.read("D0") == [0]
                reads += 1
                await anyio.sleep(0.01)

        async with anyio.create_task_group() as tg:
            tg.start_soon(sibling)
            with (
                caplog.at_level(logging.INFO, logger="aiofins.pool"),
                anyio.fail_after(3),
                pytest.raises(FrameError, match="client node 300"),  # not an ExceptionGroup
            ):
                async with pool.client(bad) as plc:  # at the borrow or the first call
                    await plc.read("D0")
            await _until(lambda: pool.stats(bad)[bad].sessions == 0)
            with pytest.raises(ConnectionLost, match="retrying in"):
                async with pool.client(bad):  # backing off: at once
                    pass
            before = reads
            await _until(lambda: reads > before + 2)  # the other PLC is still read
            tg.cancel_scope.cancel()
        stats = pool.stats(bad)[bad]
        # A typed failure of its connect (the transport checks the nodes), not an unexpected
        # error caught at the pool's boundary.
        assert (stats.connect_failures, stats.errors) == (1, 0)
        assert any(r.name == "aiofins.pool" and bad in r.getMessage() for r in caplog.records)
        async with pool.client(good) as plc:  # the pool goes on
            assert await plc.read("D0") == [0]


# -- backoff -------------------------------------------------------------------------------


async def test_endpoints_failing_together_are_retried_at_different_times(
    anyio_backend: object,
) -> None:
    """200 PLCs back after a power cut: their reconnects were in lockstep (every backoff the
    same doubling sequence). Each delay is drawn between half its ceiling and the ceiling,
    within backoff_min..backoff_max."""
    low, high = 0.02, 0.07
    urls = [f"tcp://127.0.{1 + i // 200}.{1 + i % 200}:1" for i in range(200)]  # refused
    async with Pool(backoff_min=low, backoff_max=high, max_sessions=200) as pool:
        ceilings = [2 * low, high, high]  # 2 x 0.04 is above backoff_max
        for ceiling in ceilings:

            async def fail(url: str) -> None:
                with pytest.raises(FinsError):
                    async with pool.client(url):
                        pass

            async with anyio.create_task_group() as tg:
                for url in urls:
                    tg.start_soon(fail, url)
            delays = [pool.stats(url)[url].backoff for url in urls]
            assert all(max(low, ceiling / 2) <= d <= ceiling for d in delays), ceiling
            assert len(set(delays)) > 190
            await anyio.sleep(high)  # every backoff has passed


# -- bounds --------------------------------------------------------------------------------


async def test_many_caller_chosen_hosts_do_not_open_a_socket_each(anyio_backend: object) -> None:
    """1,500 hosts named by callers (a FastAPI route): 1,015 sockets were open, then every
    new socket of the process failed. Idle sessions are evicted, least recently used first."""
    hosts = 400  # 25 times the bound: a socket each would show at once (1,500 took 46 s)
    async with Pool(max_sessions=16, timeout=5.0) as pool:
        before = _open_descriptors()
        most = 0
        for i in range(hosts):
            url = f"udp://127.3.{i // 250}.{1 + i % 250}:9600"  # nothing listens there
            async with pool.client(url) as plc:
                assert plc.session.dest.node == 1 + i % 250
            most = max(most, _open_descriptors() - before)
        assert most <= 16
        sessions = sum(s.sessions for s in pool.stats().values())
        assert sessions == 16
        last = hosts - 17  # the last one evicted
        evicted = f"udp://127.3.{last // 250}.{1 + last % 250}:9600"
        assert (pool.stats(evicted)[evicted].evictions, pool.stats(evicted)[evicted].sessions) == (
            1,
            0,
        )
        assert len(pool.stats()) <= 2 * 16  # counters of gone endpoints: bounded too


async def test_a_full_pool_of_busy_sessions_refuses_a_new_endpoint(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(max_sessions=2) as pool:
        async with pool.client(url + "?node=1") as a, pool.client(url + "?node=0") as b:
            with pytest.raises(PoolFull, match="all 2 sessions of the pool are in use"):
                async with pool.client(url + "?dest=0.1.0"):
                    pass
            assert await a.read("D0") == await b.read("D0") == [0]
        async with pool.client(url + "?dest=0.1.0") as c:  # room once one is idle
            assert await c.read("D0") == [0]
        assert sum(s.sessions for s in pool.stats().values()) == 2
    assert issubclass(PoolFull, aiofins.ConnectionLost)


async def test_a_session_whose_first_use_failed_is_released(anyio_backend: object) -> None:
    """A UDP session to a host that never answered stayed open for idle_timeout (300 s)."""
    with _silent_udp() as url:
        async with Pool(timeout=0.1, retries=0, backoff_min=5) as pool:
            with pytest.raises(FinsTimeout):
                async with pool.client(url) as plc:
                    await plc.read("D0")
            await _until(lambda: pool.stats(url)[url + ""].sessions == 0)
            stats = pool.stats(url)[url]
            assert stats.connect_failures == 1 and 5 <= stats.backoff <= 10
            with pytest.raises(ConnectionLost, match="retrying in"):
                async with pool.client(url):
                    pass


# On virtual time (trio's MockClock, asyncio on looptime's loop; uvloop's clock cannot be made
# virtual): the times below are the loop's, exact whatever the machine's load.


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_health_checks_run_side_by_side_each_within_its_timeout(backend: str) -> None:
    """They ran one after another, each up to timeout x attempts: with the defaults every
    dead endpoint held the maintenance loop ~6 s."""
    out: list[object] = []

    async def main() -> None:
        async with (
            run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as s1,
            run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as s2,
            run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as s3,
        ):
            plcs = [s1, s2, s3]
            urls = [f"udp://127.0.0.1:{s.udp_port}" for s in plcs]
            async with Pool(timeout=0.4, retries=2, health_interval=0.05, idle_timeout=60) as pool:
                for url in urls:
                    async with pool.client(url) as plc:
                        assert await plc.read("D0") == [0]
                for s in plcs:
                    s.plan.rule = FaultRule(drop_request=1.0)  # all three go silent
                started = anyio.current_time()
                await _until(lambda: all(pool.stats(u)[u].sessions == 0 for u in urls))
                out.append(anyio.current_time() - started)
                out.append([pool.stats(u)[u].health_failures for u in urls])

    run_on_virtual_time(main, backend)
    elapsed, failures = out
    # Side by side: the next pass (50 ms) plus one check's timeout, seen within the 10 ms
    # poll; one by one it took 3 x 0.4 s.
    assert 0.4 <= elapsed <= 0.4 + 0.05 + 0.01 + 1e-6, elapsed  # type: ignore[operator]
    assert failures == [1, 1, 1]


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_idle_sessions_close_while_a_health_check_waits(backend: str) -> None:
    out: list[float] = []

    async def main() -> None:
        with _silent_udp() as dead:
            async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as sim:
                good = f"udp://127.0.0.1:{sim.udp_port}"
                async with Pool(timeout=3, health_interval=0.05, idle_timeout=0.3) as pool:
                    async with pool.client(dead):  # lent, unused: its health check waits 3 s
                        pass
                    async with pool.client(good) as plc:
                        assert await plc.read("D0") == [0]
                    started = anyio.current_time()
                    await _until(lambda: pool.stats(good)[good].sessions == 0)
                    out.append(anyio.current_time() - started)

    run_on_virtual_time(main, backend)
    # Closed once idle (0.3 s, seen at the next 50 ms pass and the 10 ms poll), not after
    # the dead one's 3 s check.
    assert 0.3 <= out[0] <= 0.3 + 0.05 + 0.01 + 1e-6, out


# -- the entry state machine ---------------------------------------------------------------


async def test_an_entry_moves_only_along_its_transitions(anyio_backend: object) -> None:
    entry = _Entry("udp://h:9600", "udp://h:9600", "udp://h", None)
    assert entry.state is EntryState.CONNECTING
    changed = entry.changed
    entry.move(EntryState.READY)
    assert changed.is_set() and not entry.changed.is_set()
    with pytest.raises(RuntimeError, match="READY -> FAILED"):
        entry.move(EntryState.FAILED)
    for state in (EntryState.CHECKING, EntryState.READY, EntryState.CLOSING, EntryState.CLOSED):
        entry.move(state)
    with pytest.raises(RuntimeError, match="CLOSED -> READY"):
        entry.move(EntryState.READY)


@pytest.fixture
async def sim(anyio_backend: object) -> AsyncIterator[Simulator]:
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as running:
        yield running


async def test_a_reconnect_assigned_node_300_fails_its_endpoint_alone(sim: Simulator) -> None:
    """The issue's case: the session had worked; its reconnect's handshake assigns node 300.
    That raised out of the session's background task through the pool's task group."""
    good = f"udp://127.0.0.1:{sim.udp_port}"
    peer = TcpPeer()
    async with tcp_server(peer), Pool(timeout=1, retries=0) as pool:
        bad = f"tcp://127.0.0.1:{peer.port}"
        async with pool.client(bad) as plc:
            assert await plc.read("D0") == [0x1000]
        peer.assign_node = 300
        await peer.drop()  # the PLC resets its connections
        with anyio.fail_after(3):
            while True:  # the drop (ConnectionLost), then the reconnect's typed failure
                with pytest.raises(FinsError) as info:  # not an ExceptionGroup
                    async with pool.client(bad) as plc:
                        await plc.read("D0")
                if isinstance(info.value, FrameError):
                    break
        assert "client node 300" in str(info.value)
        async with pool.client(good) as plc:  # the rest of the pool goes on
            assert await plc.read("D0") == [0]
        stats = pool.stats(bad)[bad]
        # The session's failed reconnect, typed (the transport checks the nodes): nothing
        # unexpected reached the pool's boundary.
        assert stats.errors == 0 and stats.connect_failures >= 1


async def test_a_serial_device_carries_one_session(
    pty_pair: tuple[str, str], anyio_backend: object
) -> None:
    """Two keys of one device opened it twice: each read the other's replies."""
    _, host = pty_pair
    url = f"serial://{host}?baudrate=9600&{PTY_8N1}"
    async with Pool() as pool, pool.client(url):
        with pytest.raises(CommandError, match="a serial line carries one session"):
            async with pool.client(f"serial://{host}?baudrate=19200&{PTY_8N1}"):
                pass
        async with pool.client(url):  # the same key: shared
            (stats,) = pool.stats(url).values()
            assert stats.in_use == 2


async def test_serial_settings_at_their_defaults_share_the_session(
    pty_pair: tuple[str, str], anyio_backend: object
) -> None:
    """``serial://DEV`` and ``serial://DEV?baudrate=9600`` are the same settings: the second
    was refused as "other settings" for the open device. (A pty takes only 8N1, which every
    spelling pins.)"""
    _, host = pty_pair
    spellings = [
        f"serial://{host}?baudrate=9600&{PTY_8N1}",
        f"serial://{host}?{PTY_8N1}",
        f"serial://{host}?parity=n&unit=0&stopbits=1&bytesize=8&response_wait=0",
    ]
    async with (
        Pool() as pool,
        pool.client(spellings[0]),
        pool.client(spellings[1]),
        pool.client(spellings[2]),
    ):
        assert pool.stats(spellings[0]) == pool.stats(spellings[2])
        (stats,) = pool.stats(spellings[1]).values()
        assert (stats.sessions, stats.in_use) == (1, 3)


@pytest.mark.parametrize("timeout", ["1", True, math.nan, -1, 0, None.__class__])
async def test_a_borrowers_timeout_is_checked(sim: Simulator, timeout: Any) -> None:
    """``timeout="1"`` leaked a TypeError, ``timeout=True`` waited one second."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool() as pool:
        with pytest.raises(CommandError, match="timeout must be a positive number of seconds"):
            pool.client(url, timeout=timeout)
        async with pool.client(url, timeout=math.inf) as plc, pool.client(url, timeout=2):
            assert await plc.read("D0") == [0]


@pytest.mark.parametrize("url", [None, 5, b"udp://127.0.0.1"])
async def test_a_url_that_is_not_text_is_refused_as_connect_refuses_it(
    anyio_backend: object, url: Any
) -> None:
    """``pool.client(None)`` leaked a TypeError from the read-only check."""
    async with Pool() as pool:
        with pytest.raises(CommandError, match="the connection URL must be text"):
            pool.client(url)


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_closing_the_pool_during_a_health_check_ends_it_at_once(
    backend: str, caplog: pytest.LogCaptureFixture
) -> None:
    """On virtual time: closing takes no time at all, not the check's 5 s."""
    out: list[object] = []

    async def main() -> None:
        async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as sim:
            url = f"udp://127.0.0.1:{sim.udp_port}"
            async with Pool(timeout=5, retries=0, health_interval=0.05, idle_timeout=60) as pool:
                async with pool.client(url) as plc:
                    assert await plc.read("D0") == [0]
                sim.plan.rule = FaultRule(drop_request=1.0)  # the check waits its 5 s
                (entry,) = pool._entries[parse_endpoint(url).key]
                await _until(lambda: entry.state is EntryState.CHECKING)
                started = anyio.current_time()
            out.extend([anyio.current_time() - started, entry.state])

    run_on_virtual_time(main, backend)
    assert out == [0.0, EntryState.CLOSED]
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]


async def test_a_pool_opened_again_lends_again(sim: Simulator) -> None:
    """A second ``async with pool`` (an app's lifespan run twice, as test clients do) gave a
    pool that refused every borrower with "the pool is closed"; opening it while open lost
    the first task group."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    pool = Pool()
    for _ in range(2):
        async with pool:
            async with pool.client(url) as plc:
                assert await plc.read("D0") == [0]
            with pytest.raises(RuntimeError, match="open already"):
                async with pool:
                    pass
            async with pool.client(url) as plc:  # still open after the refused entry
                assert await plc.read("D0") == [0]
    assert pool.stats(url)[url].completed == 4
    with pytest.raises(ConnectionLost, match="the pool is closed"):
        async with pool.client(url):
            pass


async def test_an_endpoints_stats_sum_every_session_counter(anyio_backend: object) -> None:
    """pool.stats() summed 7 of the session's counters: duplicates, end-code errors, SIDs
    exhausted, breaker rejects and background errors were in no endpoint's figures."""
    faults = FaultPlan(
        rule=FaultRule(duplicate=1.0), per_command={0x0501: FaultRule(end_code=0x0401)}
    )
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=faults) as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        async with Pool() as pool, pool.client(url) as plc:
            for _ in range(3):
                assert await plc.read("D0") == [0]
            with pytest.raises(aiofins.EndCodeError):
                await plc.cpu_unit_data_read()
            await _until(lambda: plc.session.stats.duplicates >= 3)
            session = plc.session.stats.as_dict()
            stats = pool.stats(url)[url]
            assert (stats.duplicates, stats.end_code_errors) == (session["duplicates"], 1)
            for name in SESSION_COUNTERS:
                assert getattr(stats, name) == session[name], name


async def test_evicting_sessions_in_regular_use_is_a_warning(
    sim: Simulator, caplog: pytest.LogCaptureFixture
) -> None:
    """A pool smaller than the endpoints in use closed and reopened a session on nearly every
    borrow (the gateway over 1,000 PLCs with the default 256) and said so only at DEBUG."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    caplog.set_level(logging.DEBUG, logger="aiofins.pool")
    async with Pool(max_sessions=2) as pool:
        for _ in range(3):
            for query in ("?node=1", "?node=0", "?dest=0.1.0"):
                async with pool.client(url + query) as plc:
                    assert await plc.read("D0") == [0]
        evictions = sum(s.evictions for s in pool.stats().values())
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert evictions == 7  # every borrow after the first two
    assert len(warnings) == 1  # once a minute
    assert "more endpoints are in use than max_sessions=2" in warnings[0].getMessage()
    assert warnings[0].endpoint == f"{url}?node=1"  # type: ignore[attr-defined]


async def test_a_slow_name_lookup_holds_up_no_other_endpoint(
    sim: Simulator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The pool looked host names up while holding its lock: one endpoint whose name took
    long to resolve (a slow DNS server) held up the first borrow of every other endpoint.
    ``localhost`` resolves here when the test says so; ``127.0.0.1`` needs no lookup."""
    looking_up = anyio.Event()
    answer = anyio.Event()
    real_lookup = aiofins.connection.lookup

    async def slow_for_localhost(host: str, port: int, **kwargs: Any) -> list[Any]:
        if host == "localhost":
            looking_up.set()
            await answer.wait()
        return await real_lookup(host, port, **kwargs)

    monkeypatch.setattr(aiofins.connection, "lookup", slow_for_localhost)
    port = sim.udp_port
    sources: dict[str, int] = {}
    async with Pool(timeout=5) as pool:

        async def borrow(url: str) -> None:
            async with pool.client(url) as plc:
                assert await plc.read("D0") == [0]
                sources[url] = plc.session.source.node

        async with anyio.create_task_group() as tg:
            tg.start_soon(borrow, f"udp://localhost:{port}")
            await looking_up.wait()
            with anyio.fail_after(5):  # without the lookup under the lock: at once
                await borrow(f"udp://127.0.0.1:{port}")
                # a borrower's timeout bounds its lookup as it bounds its connection
                with pytest.raises(FinsTimeout, match=r"localhost was not resolved within 0.1 s"):
                    async with pool.client(f"udp://localhost:{port}?node=1", timeout=0.1):
                        pass
            assert list(sources) == [f"udp://127.0.0.1:{port}"]  # the slow one still waits
            answer.set()
        # one unit under two names: a source node each, the first borrower's the default
        assert sources == {f"udp://127.0.0.1:{port}": 254, f"udp://localhost:{port}": 253}
        assert sum(s.sessions for s in pool.stats().values()) == 2
