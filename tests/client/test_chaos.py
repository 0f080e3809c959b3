"""Under every reply fault at once, no read returns another read's data and nothing hangs."""

from __future__ import annotations

import contextlib

import anyio
import pytest

from aiofins.connection import connect
from aiofins.protocol.errors import FinsError
from aiofins.simulator.faults import Delay, FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator

from ..virtual_time import on_virtual_time

pytestmark = pytest.mark.anyio

# FINS over UDP/TCP carries no checksum of its own: a reply whose *data* bytes were corrupted
# on the way is indistinguishable from a real one (the IP and UDP/TCP checksums are what
# protect it in practice), so corruption is exercised on Host Link, where the FCS catches it
# (test_serial.py). Everything else goes wrong here at once.
CHAOS = FaultRule(
    drop_request=0.05,
    drop_response=0.05,
    delay=Delay(0.0, 0.02),
    duplicate=0.15,
    reorder=0.15,
    truncate=0.05,
)


@pytest.mark.parametrize("scheme", ["udp", "tcp"])
@on_virtual_time
async def test_reads_under_chaos_return_their_own_data(scheme: str) -> None:
    """On virtual time (asyncio, trio): each call's bound holds exactly, and how many reads
    the faults cost does not depend on the machine's load."""
    async with run_simulator(
        VirtualPLC(), udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0), faults=FaultPlan(seed=1)
    ) as sim:
        url = f"{scheme}://127.0.0.1:{sim.udp_port if scheme == 'udp' else sim.tcp_port}"
        await _reads_under_chaos(sim, url)


async def _reads_under_chaos(sim: Simulator, url: str) -> None:
    n = 100
    async with connect(url, timeout=2) as plc:
        await plc.write("D0", [(i * 3 + 1) & 0xFFFF for i in range(n)])
    sim.plan.rule = CHAOS
    timeout, retries = 0.3, 2
    outcomes: dict[int, object] = {}
    async with connect(url, timeout=timeout, retries=retries) as plc:

        async def worker(first: int) -> None:
            for i in range(first, n, 10):
                start = anyio.current_time()
                try:
                    outcomes[i] = (await plc.read(f"D{i}"))[0]
                except FinsError as exc:
                    outcomes[i] = exc
                # Bounded: each attempt waits at most timeout for a slot and for the reply.
                assert anyio.current_time() - start <= 2 * timeout * (retries + 1)

        async with anyio.create_task_group() as tg:  # 10 workers share 5 in-flight slots
            for first in range(10):
                tg.start_soon(worker, first)
        stats = plc.session.stats
    good = {i: v for i, v in outcomes.items() if isinstance(v, int)}
    assert good, "every read failed"
    wrong = {i: v for i, v in good.items() if v != (i * 3 + 1) & 0xFFFF}
    assert not wrong
    assert len(good) > n * 0.8  # retries recover most drops
    assert sim.counters.duplicated and sim.counters.reordered and sim.counters.truncated
    assert stats.duplicates + stats.late_replies + stats.malformed + stats.mismatched > 0


async def test_writes_are_never_sent_twice_without_opt_in(sim: Simulator, url: str) -> None:
    assert isinstance(sim.plc, VirtualPLC)
    sim.plan.rule = FaultRule(drop_response=0.3, duplicate=0.2, delay=Delay(0.0, 0.01))
    calls = 20
    async with connect(url, timeout=0.2, retries=3) as plc:
        before = sim.plc.commands[0x0102]
        for i in range(calls):
            with contextlib.suppress(FinsError):
                await plc.write(f"D{i}", [i])
        assert sim.plc.commands[0x0102] - before == calls  # one frame per write call
        before = sim.plc.commands[0x0102]
        failed = 0
        for i in range(calls):
            try:
                await plc.write(f"D{i}", [i], retries=3)  # opted in: retried after timeouts
            except FinsError:
                failed += 1
        assert sim.plc.commands[0x0102] - before > calls - failed
