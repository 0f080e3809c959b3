"""A scan that waits for a PLC that does not answer is no scan that cannot keep up: the
poller says what it waits for, and the timeout, the cause, is the first warning."""

from __future__ import annotations

import logging

import anyio
import pytest

from aiofins import Poller, Pool
from aiofins.simulator import FaultPlan, FaultRule, VirtualPLC, run_simulator
from aiofins.simulator.faults import Delay

pytestmark = pytest.mark.anyio


async def test_a_dead_plc_first_warns_of_its_timeout_not_of_missed_scans(
    anyio_backend: object, caplog: pytest.LogCaptureFixture
) -> None:
    plan = FaultPlan(FaultRule(drop_request=1.0), seed=1)
    caplog.set_level(logging.INFO, logger="aiofins.poller")
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=plan) as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        async with Pool(retries=0) as pool, Poller(pool) as poller:
            group = poller.add_group("g", url, {"n": "D0"}, interval=0.05, timeout=0.3)
            with anyio.fail_after(10):
                async for snap in poller:
                    if snap["n"].error is not None and group.scans >= 2:
                        break
    assert group.missed >= 1  # still counted
    records = [r for r in caplog.records if r.name == "aiofins.poller"]
    warnings = [r.getMessage() for r in records if r.levelno >= logging.WARNING]
    assert warnings, "the failing scans were not warned of"
    assert warnings[0].startswith(f"scan group g: scans of {url} fail: FinsTimeout")
    assert "scan time" in warnings[0] and "passed while it waited" in warnings[0]
    assert not [w for w in warnings if "cannot keep up" in w], warnings
    waits = [r.getMessage() for r in records if "waits for" in r.getMessage()]
    assert waits[0] == (
        f"scan group g: its scan waits for {url} to answer (timeout 0.3 s); scan times pass "
        "meanwhile (interval 0.05 s)"
    )


async def test_a_scan_that_answers_slower_than_its_interval_still_warns(
    anyio_backend: object, caplog: pytest.LogCaptureFixture
) -> None:
    plan = FaultPlan(FaultRule(delay=Delay(0.12, 0.12)), seed=1)
    caplog.set_level(logging.INFO, logger="aiofins.poller")
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), faults=plan) as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        async with Pool(retries=0) as pool, Poller(pool) as poller:
            group = poller.add_group("g", url, {"n": "D0"}, interval=0.05, timeout=2)
            with anyio.fail_after(10):
                async for snap in poller:
                    assert snap["n"].error is None
                    if group.missed and group.scans >= 2:
                        break
    warnings = [
        r.getMessage() for r in caplog.records if r.name == "aiofins.poller" and r.levelno >= 30
    ]
    assert any("cannot keep up" in w for w in warnings), warnings
