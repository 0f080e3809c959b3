"""The Poller's scans on the session's callback path (asyncio, uvloop) and on the group's
task (the first scan of a group, trio, and whenever the callback path declines), against
the simulator and hand-built peers over loopback."""

from __future__ import annotations

import logging
from collections.abc import Callable

import anyio
import pytest

from aiofins.poller import Poller, Quality, ScanGroup, ScanState, Snapshot
from aiofins.pool import Pool
from aiofins.session.callback import CallbackPending
from aiofins.simulator.faults import Delay, FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator
from aiofins.transport.base import is_asyncio

from ..session.test_session_tcp import TcpPeer, tcp_server
from ..session.test_session_udp import Reply, answer, reply, udp_responder
from ..virtual_time import on_virtual_time

pytestmark = pytest.mark.anyio


def count_task_scans(poller: Poller) -> list[str]:
    """Record every scan the groups' tasks make (``scan_once``): the callback path makes
    none."""
    calls: list[str] = []
    scan_once = poller.scan_once

    async def counted(group: ScanGroup) -> Snapshot | None:
        calls.append(group.name)
        return await scan_once(group)

    poller.scan_once = counted  # type: ignore[method-assign]
    return calls


async def take(
    poller: Poller, n: int, check: Callable[[Snapshot], None] | None = None
) -> list[Snapshot]:
    snaps: list[Snapshot] = []
    with anyio.fail_after(10):
        async for snap in poller:
            if check is not None:
                check(snap)
            snaps.append(snap)
            if len(snaps) == n:
                break
    return snaps


async def until(condition: Callable[[], bool]) -> None:
    with anyio.fail_after(10):
        while not condition():
            await anyio.sleep(0.005)


async def test_scans_after_the_first_wake_no_task_under_asyncio(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    tags = {"t": "D10:float32", "n": "D12:uint32", "b": "D14.03", "w": "D15", "s": "D16:bcd16"}
    async with Pool(timeout=1) as pool:
        async with pool.client(url) as plc:
            await plc.write_value("D10", 12.5, "float32")
            await plc.write("D12", [0x5678, 0x1234, 0x0008, 7, 0x0042])
        async with Poller(pool) as poller:
            tasks = count_task_scans(poller)
            group = poller.add_group("g", url, tags, interval=0.01)
            snaps = await take(poller, 6)
        assert [s.scan for s in snaps] == [1, 2, 3, 4, 5, 6]
        for snap in snaps:
            assert snap.error is None
            assert snap.values == {"t": 12.5, "n": 0x12345678, "b": True, "w": 7, "s": 42}
            assert list(snap.readings) == ["t", "n", "b", "w", "s"]
            assert snap["n"].quality is Quality.GOOD and snap["n"].timestamp == snap.timestamp
        assert snaps[0].changed == {"t", "n", "b", "w", "s"} and snaps[1].changed == set()
        # The first scan compiles the plan on the group's task; then the callback path.
        if is_asyncio():
            assert tasks == ["g"]
        else:  # every scan on the group's task; a 7th may begin before the consumer stops
            assert tasks[:6] == ["g"] * 6 and set(tasks) == {"g"}
        assert group.errors == 0 and group.state is ScanState.STOPPED
        (stats,) = pool.stats(url).values()
        assert stats.in_use == 0


async def test_a_scan_in_flight_holds_its_lease_and_its_state(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=2) as pool:
        async with Poller(pool) as poller:
            group = poller.add_group("g", url, {"a": "D0"}, interval=0.05)
            await take(poller, 1)
            sim.plan.rule = FaultRule(delay=Delay(0.2, 0.2))
            await until(lambda: group.state is ScanState.SCANNING)
            (stats,) = pool.stats(url).values()
            assert stats.in_use == 1  # borrowed: the pool neither lends it as idle nor closes it
            request = group._in_flight()
            assert (request is not None) is is_asyncio()
            if request is not None:  # a plan of one frame: one request, no batch
                assert isinstance(request, CallbackPending) and group._scan is None
            await take(poller, 1)
        (stats,) = pool.stats(url).values()
        assert stats.in_use == 0 and group._in_flight() is None


async def test_leaving_with_a_scan_in_flight_gives_everything_back(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=5) as pool:
        async with Poller(pool) as poller:
            group = poller.add_group("g", url, {"a": "D0"}, interval=0.05)
            await take(poller, 1)
            sim.plan.rule = FaultRule(drop_request=1.0)
            await until(lambda: group.state is ScanState.SCANNING)
        assert group.state is ScanState.STOPPED and group._in_flight() is None
        (stats,) = pool.stats(url).values()
        assert stats.in_use == 0
        async with pool.client(url) as plc:
            session = plc.session
            assert session.stats.in_flight == 0  # the scan's SID quarantined, not pending
            assert all(s.slots.in_flight == 0 for s in session._dests.values())


@on_virtual_time
async def test_an_outage_is_counted_logged_once_and_its_end_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """On virtual time (asyncio's callback path and trio's task path; uvloop's clock cannot
    be virtual): the 50 ms timeout ends only the scans of the outage, never a loaded
    machine's slow answer."""
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
        await _an_outage_is_counted_logged_once_and_its_end_logged(sim, caplog)


async def _an_outage_is_counted_logged_once_and_its_end_logged(
    sim: Simulator, caplog: pytest.LogCaptureFixture
) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=0.05, retries=0) as pool:
        async with pool.client(url) as plc:
            await plc.write("D0", [5])
        with caplog.at_level(logging.INFO, "aiofins.poller"):
            async with Poller(pool) as poller:
                tasks = count_task_scans(poller)
                group = poller.add_group("g", url, {"a": "D0"}, interval=0.01)
                await take(poller, 2)
                sim.plan.rule = FaultRule(drop_request=1.0)
                bad = await take(poller, 4, lambda s: None)
                sim.plan.rule = FaultRule()
                good = await take(poller, 3, lambda s: None)
        failed = [s for s in bad if s.error is not None]
        assert len(failed) == 4  # every scan of the outage, exactly
        for snap in failed:
            assert snap.error is not None and snap.error.startswith("FinsTimeout: no response")
            assert snap["a"].quality is Quality.STALE and snap["a"].value == 5
        assert good[-1].error is None and good[-1]["a"].quality is Quality.GOOD
        assert group.errors == len(failed)
        messages = [r.getMessage() for r in caplog.records]
        assert sum("scans of" in m and " fail: FinsTimeout" in m for m in messages) == 1
        assert sum("succeed again" in m for m in messages) == 1
        if is_asyncio():
            assert tasks == ["g"]  # the failed scans too ended in the session's callbacks


async def test_busy_end_codes_and_late_replies_on_the_callback_path() -> None:
    seen = 0

    def flaky(cmd: bytes) -> list[Reply]:
        nonlocal seen
        seen += 1
        if seen % 3 == 2:
            return [(0.0, reply(cmd, 0x2604))]  # busy: sent again after a pause
        if seen % 3 == 0:  # an answer, then a duplicate of it later (dropped, counted)
            good = answer(cmd)[0][1]
            return [(0.0, good), (0.05, good)]
        return answer(cmd)

    async with udp_responder(flaky) as peer:
        url = f"udp://127.0.0.1:{peer.port}"
        async with Pool(timeout=1) as pool, Poller(pool) as poller:
            group = poller.add_group("g", url, {"a": "D100", "b": "D101"}, interval=0.02)
            snaps = await take(poller, 8)
            async with pool.client(url) as plc:
                stats = plc.session.stats
                await until(lambda: stats.duplicates + stats.late_replies >= 1)
        for snap in snaps:
            assert snap.error is None
            assert snap.values == {"a": (1 << 12) ^ 100, "b": (1 << 12) ^ 101}
        assert stats.busy_retries >= 2 and group.errors == 0


async def test_a_link_that_dies_mid_scan_fails_that_scan_then_recovers() -> None:
    hold = anyio.Event()
    held: list[bytes] = []

    def answer_unless_held(cmd: bytes) -> bytes | None:
        if not hold.is_set():
            held.append(cmd)
            return None  # the scan waits for a reply that will not come
        return reply(cmd, 0, b"\x00\x07\x00\x08")

    peer = TcpPeer(answer=answer_unless_held)
    async with tcp_server(peer):
        url = f"tcp://127.0.0.1:{peer.port}"
        async with Pool(timeout=5, backoff_min=0.0) as pool, Poller(pool) as poller:
            group = poller.add_group("g", url, {"a": "D0", "b": "D1"}, interval=0.02)
            hold.set()
            first = await take(poller, 1)
            hold = anyio.Event()
            await until(lambda: bool(held))
            assert group.state is ScanState.SCANNING
            await peer.drop()  # the PLC resets its connections mid-scan
            hold.set()
            after = await take(poller, 3)
        assert first[0].values == {"a": 7, "b": 8}
        assert after[0].error is not None and "ConnectionLost" in after[0].error
        assert after[0]["a"].quality is Quality.STALE
        assert after[-1].error is None and after[-1].values == {"a": 7, "b": 8}
        assert group.errors == 1


@on_virtual_time
async def test_an_open_breaker_sends_scans_to_the_task_path_until_it_closes() -> None:
    """On virtual time (asyncio, trio; uvloop's clock cannot be virtual): the short timeout
    ends only the scans of the outage, never a loaded machine's slow answer."""
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=FaultPlan()) as sim:
        await _test_an_open_breaker_sends_scans_to_the_task_path_until_it_closes(sim)


async def _test_an_open_breaker_sends_scans_to_the_task_path_until_it_closes(
    sim: Simulator,
) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=0.05, retries=0) as pool, Poller(pool) as poller:
        tasks = count_task_scans(poller)
        poller.add_group("g", url, {"a": "D0"}, interval=0.01)
        await take(poller, 1)
        sim.plan.rule = FaultRule(drop_request=1.0)
        errors = [s.error or "" for s in await take(poller, 12)]  # 5 in a row: open
        assert any(e.startswith("CircuitOpen") for e in errors)
        assert sum(e.startswith("FinsTimeout") for e in errors) >= 5
        if is_asyncio():  # the breaker was open: the group's task scanned
            assert len(tasks) > 1
        sim.plan.rule = FaultRule()

        def good(snap: Snapshot) -> bool:
            return snap.error is None

        with anyio.fail_after(10):
            async for snap in poller:
                if good(snap):
                    break
        before = len(tasks)
        assert all(good(s) for s in await take(poller, 5))
        if is_asyncio():  # closed again: back on the callback path
            assert len(tasks) <= before + 1


async def test_a_full_buffer_makes_callback_scans_wait_in_order(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with Pool(timeout=1) as pool:
        async with Poller(pool, buffer=1) as poller:
            group = poller.add_group("g", url, {"a": "D0"}, interval=0.005)
            await until(lambda: group.state is ScanState.DELIVERING)
            await until(lambda: group.missed > 0)  # the consumer is slow: scans are missed
            snaps = await take(poller, 6)
        numbers = [s.scan for s in snaps]
        assert numbers == sorted(numbers) and len(set(numbers)) == 6


async def test_uvloop_and_asyncio_share_one_scan_result(
    sim: Simulator, anyio_backend: object
) -> None:
    """The same 20 tags decode alike on every backend (callback and task paths)."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    tags = {
        **{f"f{i}": f"D{2 * i}:float32" for i in range(5)},
        **{f"c{i}": f"D{10 + 2 * i}:uint32" for i in range(5)},
        **{f"b{i}": f"D20.{i:02d}" for i in range(5)},
        **{f"w{i}": f"D{21 + i}" for i in range(5)},
    }
    async with Pool(timeout=1) as pool:
        async with pool.client(url) as plc:
            for i in range(5):
                await plc.write_value(f"D{2 * i}", i + 0.5, "float32")
                await plc.write_value(f"D{10 + 2 * i}", 70000 + i, "uint32")
            await plc.write("D20", [0b10101, 1, 2, 3, 4, 5])
        async with Poller(pool) as poller:
            poller.add_group("g", url, tags, interval=0.01)
            snaps = await take(poller, 3)
    want = {
        **{f"f{i}": i + 0.5 for i in range(5)},
        **{f"c{i}": 70000 + i for i in range(5)},
        **{f"b{i}": i % 2 == 0 for i in range(5)},
        **{f"w{i}": i + 1 for i in range(5)},
    }
    for snap in snaps:
        assert snap.values == want and list(snap.readings) == list(tags)
        assert {name: snap[name].value for name in tags} == want


async def test_a_short_reply_fails_its_scan_and_the_group_goes_on() -> None:
    short = True

    def maybe_short(cmd: bytes) -> list[Reply]:
        if short:
            return [(0.0, reply(cmd, 0, b"\x00\x01"))]  # one word of the two asked
        return answer(cmd)

    async with udp_responder(maybe_short) as peer:
        url = f"udp://127.0.0.1:{peer.port}"
        async with Pool(timeout=1) as pool, Poller(pool) as poller:
            group = poller.add_group("g", url, {"a": "D100", "b": "D101"}, interval=0.01)
            bad = await take(poller, 3)
            short = False
            with anyio.fail_after(10):
                async for good in poller:
                    if good.error is None:
                        break
    for snap in bad:
        assert snap.error is not None and snap.error.startswith("DecodeError: MEMORY AREA READ")
        assert snap["a"].quality is Quality.ERROR and snap["a"].value is None
    assert good.values == {"a": (1 << 12) ^ 100, "b": (1 << 12) ^ 101}
    assert group.errors >= 3


async def test_a_plan_of_several_frames_and_strings_scans_on_the_callback_path(
    sim: Simulator,
) -> None:
    """0101 and 0104 frames pipelined in one callback scan; a string tag (no bulk decode)
    decoded by name."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    tags = {"s": "D0:string:400", "x": "D5000", "y": "D9000.03"}
    async with Pool(timeout=1) as pool:
        async with pool.client(url) as plc:
            await plc.write_value("D0", "hello", "string:400")
            await plc.write("D5000", [7])
            await plc.write("D9000", [8])
            plan = plc.compile_tags(tags)
            assert (len(plan.runs), len(plan.multiple)) == (1, 1)
        async with Poller(pool) as poller:
            tasks = count_task_scans(poller)
            poller.add_group("g", url, tags, interval=0.01)
            snaps = await take(poller, 4)
    for snap in snaps:
        assert snap.error is None and snap.values == {"s": "hello", "x": 7, "y": True}
    assert tasks == (["g"] if is_asyncio() else ["g"] * 4)


async def test_cpu_error_flags_in_a_reply_leave_the_scan_good_and_are_kept() -> None:
    """A reply whose end code carries a non-fatal CPU error flag (0x0040) is a normal
    completion: the scan is GOOD (decoded from the frame) and the end code is the client's
    ``last_end_code``, on the callback path as on the task path."""

    def flagged(cmd: bytes) -> list[Reply]:
        return [(0.0, reply(cmd, 0x0040, b"\x00\x05\x00\x06"))]

    async with udp_responder(flagged) as peer:
        url = f"udp://127.0.0.1:{peer.port}"
        async with Pool(timeout=1) as pool, Poller(pool) as poller:
            tasks = count_task_scans(poller)
            poller.add_group("g", url, {"a": "D100", "b": "D101"}, interval=0.01)
            snaps = await take(poller, 3)
            async with pool.client(url) as plc:
                assert plc.last_end_code is not None and plc.last_end_code.raw == 0x0040
    for snap in snaps:
        assert snap.error is None and snap.values == {"a": 5, "b": 6}
        assert snap["a"].quality is Quality.GOOD
    assert tasks == (["g"] if is_asyncio() else ["g"] * 3)
